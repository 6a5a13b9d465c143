#include "avp/ros/mcap/mcap.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::ros::mcap {
namespace {

using ::testing::HasSubstr;

std::vector<uint8_t> Slurp(const std::filesystem::path& p) {
  const std::string bytes = test::ReadWholeFile(p);
  return {bytes.begin(), bytes.end()};
}
void Spit(const std::filesystem::path& p, const std::vector<uint8_t>& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

/// 30 messages on two channels, payloads of 100 + i bytes, log times 1000 + 10 i (channel 0) and
/// 1005 + 10 i (channel 1); chunks of ~1 KB so the file has several, stored with `compression`.
std::vector<Message> WriteSample(const std::filesystem::path& path, uint64_t chunk_size = 1024,
                                 const std::string& compression = "") {
  auto w = Writer::Open(path, {.chunk_size = chunk_size, .compression = compression}).value();
  const uint16_t schema = w->AddSchema("std_msgs/msg/String", "ros2msg", "string data\n").value();
  EXPECT_EQ(schema, 1);
  EXPECT_EQ(
      w->AddChannel(schema, "/a", "cdr", {{"offered_qos_profiles", OfferedQosProfiles()}}).value(),
      0);
  EXPECT_EQ(w->AddChannel(schema, "/b", "cdr").value(), 1);
  std::vector<Message> messages;
  for (uint32_t i = 0; i < 30; ++i) {
    Message m;
    m.channel_id = static_cast<uint16_t>(i % 2);
    m.sequence = i;
    m.log_time = 1000 + 5 * i;
    m.publish_time = 900 + 5 * i;
    m.data.assign(100 + i, static_cast<uint8_t>(i));
    EXPECT_TRUE(w->Write(m).ok());
    messages.push_back(m);
  }
  const Status closed = w->Close();
  EXPECT_TRUE(closed.ok()) << closed.ToString();
  return messages;
}

class McapTest : public test::TempDirTest {};

TEST(McapCrcTest, KnownValue) {
  const std::string s = "123456789";
  EXPECT_EQ(Crc32({reinterpret_cast<const uint8_t*>(s.data()), s.size()}), 0xCBF43926u);
  // Continuing a CRC equals the CRC of the whole.
  const uint32_t part = Crc32({reinterpret_cast<const uint8_t*>(s.data()), 4});
  EXPECT_EQ(Crc32({reinterpret_cast<const uint8_t*>(s.data()) + 4, 5}, part), 0xCBF43926u);
}

TEST(McapCrcTest, SlicedEqualsBitwiseAtEveryLengthAndSplit) {
  std::vector<uint8_t> bytes(300);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<uint8_t>(i * 131 + 7);
  const auto bitwise = [](std::span<const uint8_t> b) {
    uint32_t c = 0xFFFFFFFFu;
    for (uint8_t x : b) {
      c ^= x;
      for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    }
    return ~c;
  };
  for (size_t n = 0; n <= bytes.size(); ++n) {
    const std::span<const uint8_t> b(bytes.data(), n);
    ASSERT_EQ(Crc32(b), bitwise(b)) << n;
    const size_t half = n / 3;
    ASSERT_EQ(Crc32(b.subspan(half), Crc32(b.first(half))), bitwise(b)) << n;
  }
}

TEST_F(McapTest, RoundTripIndexedAndStreaming) {
  const auto path = dir_ / "a.mcap";
  const std::vector<Message> written = WriteSample(path);
  const std::vector<uint8_t> bytes = Slurp(path);
  ASSERT_GE(bytes.size(), 16u);
  EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + 8), std::string(kMagic));
  EXPECT_EQ(std::string(bytes.end() - 8, bytes.end()), std::string(kMagic));

  const File indexed = ReadIndexed(path).value();
  EXPECT_EQ(indexed.profile, "ros2");
  EXPECT_EQ(indexed.library, "avp");
  ASSERT_EQ(indexed.schemas.size(), 1u);
  EXPECT_EQ(indexed.schemas[0].name, "std_msgs/msg/String");
  EXPECT_EQ(indexed.schemas[0].encoding, "ros2msg");
  EXPECT_EQ(indexed.schemas[0].data, "string data\n");
  ASSERT_EQ(indexed.channels.size(), 2u);
  EXPECT_EQ(indexed.channels[0].topic, "/a");
  EXPECT_EQ(indexed.channels[0].message_encoding, "cdr");
  EXPECT_THAT(indexed.channels[0].metadata.at("offered_qos_profiles"),
              HasSubstr("reliability: 1\n  durability: 2"));
  EXPECT_EQ(indexed.messages, written);
  EXPECT_GT(indexed.chunk_count, 2u);

  const StreamResult streamed = ReadStreaming(path);
  ASSERT_TRUE(streamed.status.ok()) << streamed.status.ToString();
  EXPECT_EQ(streamed.intact_bytes, bytes.size());
  EXPECT_EQ(streamed.file.messages, written);
  EXPECT_EQ(streamed.file.schemas, indexed.schemas);
  EXPECT_EQ(streamed.file.channels, indexed.channels);
  EXPECT_EQ(streamed.file.chunk_count, indexed.chunk_count);
}

TEST_F(McapTest, CompressedChunksRoundTripAndDamageIsNamedNeverACrash) {
  WriteSample(dir_ / "plain.mcap", 1024);
  for (const std::string compression : {"zstd", "lz4"}) {
    const auto path = dir_ / (compression + ".mcap");
    const std::vector<Message> written = WriteSample(path, 1024, compression);
    const File indexed = ReadIndexed(path).value();
    EXPECT_EQ(indexed.messages, written) << compression;
    EXPECT_GT(indexed.chunk_count, 2u);
    const StreamResult streamed = ReadStreaming(path);
    ASSERT_TRUE(streamed.status.ok()) << streamed.status.ToString();
    EXPECT_EQ(streamed.file.messages, written) << compression;
    // The payloads repeat one byte: stored compressed, the file is far smaller than the records.
    EXPECT_LT(Slurp(path).size(), Slurp(dir_ / "plain.mcap").size() / 2) << compression;
    // Every flipped byte is found (a chunk that does not decompress, a CRC) or harmless.
    const std::vector<uint8_t> good = Slurp(path);
    const auto bad_path = dir_ / "bad.mcap";
    for (size_t i = 0; i < good.size(); ++i) {
      std::vector<uint8_t> bytes = good;
      bytes[i] ^= 0x5A;
      Spit(bad_path, bytes);
      const StreamResult s = ReadStreaming(bad_path);
      if (!s.status.ok()) {
        EXPECT_THAT(s.status.message(), HasSubstr(bad_path.string())) << "byte " << i;
      }
      for (const Message& m : s.file.messages) {
        ASSERT_LT(m.sequence, written.size()) << compression << " byte " << i;
        ASSERT_EQ(m, written[m.sequence]) << compression << " byte " << i;
      }
    }
  }
  const Result<std::unique_ptr<Writer>> bz2 =
      Writer::Open(dir_ / "x.mcap", {.chunk_size = 1024, .compression = "bz2"});
  ASSERT_FALSE(bz2.ok());
  EXPECT_THAT(bz2.status().message(), HasSubstr("'bz2' is not one avp writes (none, zstd or lz4)"));
}

TEST_F(McapTest, SummaryStatistics) {
  const auto path = dir_ / "s.mcap";
  WriteSample(path);
  const File f = ReadIndexed(path).value();
  const Statistics& s = f.statistics;
  EXPECT_EQ(s.message_count, 30u);
  EXPECT_EQ(s.schema_count, 1);
  EXPECT_EQ(s.channel_count, 2u);
  EXPECT_EQ(s.attachment_count, 0u);
  EXPECT_EQ(s.metadata_count, 0u);
  EXPECT_EQ(s.chunk_count, f.chunk_count);
  EXPECT_EQ(s.message_start_time, 1000u);
  EXPECT_EQ(s.message_end_time, 1000u + 5 * 29);
  EXPECT_EQ(s.channel_message_counts, (std::map<uint16_t, uint64_t>{{0, 15}, {1, 15}}));
  // ~1 KB chunks of 100..129-byte messages (+31 bytes of record each): 7 or 8 per chunk.
  EXPECT_GE(s.chunk_count, 4u);
  EXPECT_LE(s.chunk_count, 5u);
  // The streaming reader counts the same.
  EXPECT_EQ(ReadStreaming(path).file.statistics, s);
}

TEST_F(McapTest, EmptyFile) {
  const auto path = dir_ / "e.mcap";
  ASSERT_TRUE(Writer::Open(path).value()->Close().ok());
  const File f = ReadIndexed(path).value();
  EXPECT_TRUE(f.messages.empty());
  EXPECT_EQ(f.statistics.message_count, 0u);
  EXPECT_EQ(f.statistics.chunk_count, 0u);
  EXPECT_TRUE(ReadStreaming(path).status.ok());
}

TEST_F(McapTest, ChunkCrcMismatchNamesTheOffset) {
  const auto path = dir_ / "c.mcap";
  WriteSample(path);
  std::vector<uint8_t> bytes = Slurp(path);
  const File f = ReadIndexed(path).value();
  // Flip one payload byte of message 20 (its payload bytes are all 20).
  const std::vector<uint8_t> needle(120, 20);
  auto it = std::search(bytes.begin(), bytes.end(), needle.begin(), needle.end());
  ASSERT_NE(it, bytes.end());
  *(it + 50) ^= 0xFF;
  Spit(path, bytes);

  const Status indexed = ReadIndexed(path).status();
  EXPECT_EQ(indexed.code(), StatusCode::kParseError);
  EXPECT_THAT(indexed.message(), HasSubstr(path.string()));
  EXPECT_THAT(indexed.message(), HasSubstr("CRC mismatch in the chunk at offset "));

  const StreamResult streamed = ReadStreaming(path);
  EXPECT_THAT(streamed.status.message(), HasSubstr("CRC mismatch in the chunk at offset "));
  EXPECT_THAT(streamed.status.message(), HasSubstr(path.string()));
  // Messages of the intact chunks before the bad one; none of the bad chunk.
  ASSERT_FALSE(streamed.file.messages.empty());
  EXPECT_LT(streamed.file.messages.back().sequence, 20u);
  for (size_t i = 0; i < streamed.file.messages.size(); ++i) {
    EXPECT_EQ(streamed.file.messages[i], f.messages[i]);
  }
  EXPECT_THAT(streamed.status.message(),
              HasSubstr("offset " + std::to_string(streamed.intact_bytes)));
}

TEST_F(McapTest, SummaryCrcMismatch) {
  const auto path = dir_ / "m.mcap";
  WriteSample(path);
  std::vector<uint8_t> bytes = Slurp(path);
  // The schema text appears first in the data section and again in the summary: damage the second.
  const std::string needle = "string data\n";
  auto first = std::search(bytes.begin(), bytes.end(), needle.begin(), needle.end());
  auto second = std::search(first + 1, bytes.end(), needle.begin(), needle.end());
  ASSERT_NE(second, bytes.end());
  *second = 'S';
  Spit(path, bytes);
  const Status s = ReadIndexed(path).status();
  EXPECT_THAT(s.message(), HasSubstr("summary CRC mismatch (summary at offset "));
  // The data section is intact: the streaming reader returns all 30 messages.
  EXPECT_EQ(ReadStreaming(path).file.messages.size(), 30u);
}

TEST_F(McapTest, TruncatedFileNamesTheOffsetAndKeepsIntactChunks) {
  const auto path = dir_ / "t.mcap";
  const std::vector<Message> written = WriteSample(path);
  const std::vector<uint8_t> bytes = Slurp(path);
  const auto cut_path = dir_ / "cut.mcap";
  size_t previous = 0;
  for (size_t cut : {size_t{20}, size_t{600}, size_t{1500}, size_t{2500}, size_t{3600},
                     bytes.size() / 2, bytes.size() - 9, bytes.size() - 1}) {
    SCOPED_TRACE("cut at " + std::to_string(cut));
    Spit(cut_path, std::vector<uint8_t>(bytes.begin(), bytes.begin() + static_cast<long>(cut)));
    const Status indexed = ReadIndexed(cut_path).status();
    EXPECT_EQ(indexed.code(), StatusCode::kParseError);
    EXPECT_THAT(indexed.message(), HasSubstr(cut_path.string()));

    const StreamResult s = ReadStreaming(cut_path);
    EXPECT_EQ(s.status.code(), StatusCode::kParseError);
    EXPECT_THAT(s.status.message(), HasSubstr(cut_path.string()));
    EXPECT_THAT(s.status.message(), HasSubstr("offset " + std::to_string(s.intact_bytes)));
    EXPECT_GT(s.intact_bytes, 0u);
    EXPECT_LE(s.intact_bytes, cut);
    // A prefix of what was written, and more the later the cut.
    ASSERT_LE(s.file.messages.size(), written.size());
    for (size_t i = 0; i < s.file.messages.size(); ++i) EXPECT_EQ(s.file.messages[i], written[i]);
    EXPECT_GE(s.file.messages.size(), previous);
    previous = s.file.messages.size();
  }
  // Past the data section (cut in the summary) every message is intact.
  EXPECT_EQ(previous, written.size());
}

TEST_F(McapTest, EveryFlippedByteIsDetectedOrHarmlessNeverACrash) {
  const auto path = dir_ / "g.mcap";
  const std::vector<Message> written = WriteSample(path, 1024);
  const std::vector<uint8_t> good = Slurp(path);
  const auto bad_path = dir_ / "bad.mcap";
  size_t streaming_errors = 0;
  for (size_t i = 0; i < good.size(); ++i) {
    std::vector<uint8_t> bytes = good;
    bytes[i] ^= 0x5A;
    Spit(bad_path, bytes);
    const Result<File> indexed = ReadIndexed(bad_path);
    if (!indexed.ok()) {
      EXPECT_THAT(indexed.status().message(), HasSubstr(bad_path.string()));
    }
    const StreamResult s = ReadStreaming(bad_path);
    if (!s.status.ok()) {
      ++streaming_errors;
      EXPECT_THAT(s.status.message(), HasSubstr(bad_path.string())) << "byte " << i;
      // What it kept is genuine: messages of chunks whose CRC held (a chunk whose opcode was hit
      // is an unknown record, skipped as the spec says, and only the Data End CRC then fails).
      for (const Message& m : s.file.messages) {
        ASSERT_LT(m.sequence, written.size()) << "byte " << i;
        ASSERT_EQ(m, written[m.sequence]) << "byte " << i;
      }
    }
  }
  // The data section is under the Data End CRC, so every flip before the summary is caught by the
  // streaming reader; the summary's flips are not its concern.
  const uint64_t summary_start = [&] {
    uint64_t v = 0;
    const size_t at = good.size() - 8 - 20;  // the Footer's summary_start
    for (size_t k = 0; k < 8; ++k) v |= static_cast<uint64_t>(good[at + k]) << (8 * k);
    return v;
  }();
  EXPECT_GE(streaming_errors, summary_start);
}

TEST_F(McapTest, FlushWritesTheChunkSoAnUnclosedFileKeepsIt) {
  const auto path = dir_ / "f.mcap";
  auto w = Writer::Open(path).value();
  const uint16_t sc = w->AddSchema("std_msgs/msg/String", "ros2msg", "string data\n").value();
  const uint16_t ch = w->AddChannel(sc, "/a", "cdr").value();
  const std::vector<uint8_t> payload = {0, 1, 0, 0, 2, 0, 0, 0, 'x', 0};
  ASSERT_TRUE(w->Write(ch, 7, 123, 120, payload).ok());
  ASSERT_TRUE(w->Flush().ok());
  const StreamResult s = ReadStreaming(path);  // the writer is still open
  EXPECT_THAT(s.status.message(), HasSubstr("without a Data End record"));
  ASSERT_EQ(s.file.messages.size(), 1u);
  EXPECT_EQ(s.file.messages[0].sequence, 7u);
  EXPECT_EQ(s.file.messages[0].log_time, 123u);
  EXPECT_EQ(s.file.messages[0].data, payload);
  ASSERT_TRUE(w->Close().ok());
  EXPECT_EQ(ReadIndexed(path).value().messages.size(), 1u);
}

TEST_F(McapTest, AttachmentsAndMetadataRoundTrip) {
  const auto path = dir_ / "am.mcap";
  auto w = Writer::Open(path, {.chunk_size = 256, .compression = ""}).value();
  const uint16_t sc = w->AddSchema("std_msgs/msg/String", "ros2msg", "string data\n").value();
  const uint16_t ch = w->AddChannel(sc, "/a", "cdr").value();
  const Metadata avp{"avp", {{"command", "avp run"}, {"seed", "7"}, {"empty", ""}}};
  const Metadata other{"other", {}};
  ASSERT_TRUE(w->WriteMetadata(avp).ok());
  Attachment gt{1'700'000'000'000'000'001ull, 42, "ground_truth.json", "application/json",
                R"({"fruits": [1, 2, 3]})"};
  Attachment binary{5, 6, "bytes.bin", "application/octet-stream", std::string("\0\x01\xff", 3)};
  ASSERT_TRUE(w->WriteAttachment(gt).ok());
  std::vector<Message> written;
  for (uint32_t i = 0; i < 12; ++i) {
    Message m{ch, i, 100 + i, 100 + i, std::vector<uint8_t>(60, static_cast<uint8_t>(i))};
    ASSERT_TRUE(w->Write(m).ok());
    written.push_back(m);
    if (i == 5) {
      ASSERT_TRUE(w->WriteAttachment(binary).ok());  // between chunks
      ASSERT_TRUE(w->WriteMetadata(other).ok());
    }
  }
  ASSERT_TRUE(w->Close().ok());
  EXPECT_EQ(w->statistics().attachment_count, 2u);
  EXPECT_EQ(w->statistics().metadata_count, 2u);

  const File indexed = ReadIndexed(path).value();
  EXPECT_EQ(indexed.attachments, (std::vector<Attachment>{gt, binary}));
  EXPECT_EQ(indexed.metadata, (std::vector<Metadata>{avp, other}));
  EXPECT_EQ(indexed.messages, written);
  EXPECT_EQ(indexed.statistics.attachment_count, 2u);
  EXPECT_EQ(indexed.statistics.metadata_count, 2u);
  EXPECT_GT(indexed.chunk_count, 1u);

  const StreamResult streamed = ReadStreaming(path);
  ASSERT_TRUE(streamed.status.ok()) << streamed.status.ToString();
  EXPECT_EQ(streamed.file.attachments, indexed.attachments);
  EXPECT_EQ(streamed.file.metadata, indexed.metadata);
  EXPECT_EQ(streamed.file.messages, written);
  EXPECT_EQ(streamed.file.statistics, indexed.statistics);
}

TEST_F(McapTest, AttachmentCrcMismatchNamesTheAttachmentAndOffset) {
  const auto path = dir_ / "ac.mcap";
  auto w = Writer::Open(path).value();
  ASSERT_TRUE(w->WriteAttachment({1, 2, "gt.json", "application/json", "{\"abcdefgh\": 1}"}).ok());
  ASSERT_TRUE(w->Close().ok());
  std::vector<uint8_t> bytes = Slurp(path);
  const std::string needle = "abcdefgh";
  auto it = std::search(bytes.begin(), bytes.end(), needle.begin(), needle.end());
  ASSERT_NE(it, bytes.end());
  *it = 'X';
  Spit(path, bytes);
  // The attachment record starts right after the magic and the Header record.
  const std::string offset = std::to_string(8 + 9 + 4 + 4 + 4 + 3);
  const Status indexed = ReadIndexed(path).status();
  EXPECT_THAT(indexed.message(),
              HasSubstr("CRC mismatch in the attachment 'gt.json' at offset " + offset));
  EXPECT_THAT(indexed.message(), HasSubstr(path.string()));
  const StreamResult streamed = ReadStreaming(path);
  EXPECT_THAT(streamed.status.message(),
              HasSubstr("CRC mismatch in the attachment 'gt.json' at offset " + offset));
  EXPECT_TRUE(streamed.file.attachments.empty());
}

TEST_F(McapTest, ErrorsNameTheFileAndTheValue) {
  const auto path = dir_ / "x.mcap";
  auto w = Writer::Open(path).value();
  EXPECT_THAT(w->AddChannel(3, "/a", "cdr").status().message(),
              HasSubstr("channel '/a': no schema with id 3"));
  EXPECT_THAT(w->Write(5, 0, 0, 0, {}).message(), HasSubstr("message on channel 5"));
  EXPECT_THAT(w->Write(5, 0, 0, 0, {}).message(), HasSubstr(path.string()));
  ASSERT_TRUE(w->Close().ok());
  EXPECT_THAT(w->Write(0, 0, 0, 0, {}).message(), HasSubstr("after Close()"));
  EXPECT_THAT(Writer::Open(dir_ / "no" / "such.mcap").status().message(),
              HasSubstr("such.mcap: cannot create"));
  EXPECT_THAT(ReadIndexed(dir_ / "missing.mcap").status().message(),
              HasSubstr("missing.mcap: cannot open"));
  Spit(dir_ / "not.mcap", {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd'});
  EXPECT_THAT(ReadStreaming(dir_ / "not.mcap").status.message(),
              HasSubstr("not an MCAP file: no magic at offset 0"));
}

}  // namespace
}  // namespace avp::ros::mcap
