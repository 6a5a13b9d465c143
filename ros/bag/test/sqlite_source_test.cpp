// rosbag2 SQLite 3 bags (.db3) and bag folders (metadata.yaml): .db3 files written here with the
// SQLite C API in the schemas rosbag2 writes (Dashing/Eloquent without offered_qos_profiles, Foxy,
// Humble with its schema and metadata tables, Jazzy with message_definitions), holding real CDR
// messages inserted out of time order; per-message zstd; damaged and foreign files; every error of
// metadata.yaml.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <zstd.h>

#include <avp/ros/bag/message_source.h>
#include <avp/ros/mcap/mcap.h>
#include <avp/ros/msg/messages.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::ros::bag {
namespace {

namespace fs = std::filesystem;

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::Pair;
using ::testing::StartsWith;

constexpr uint64_t kT0 = 1'690'000'000'000'000'000;  // ns since the epoch

// ---- Writing .db3 files as rosbag2 does ---------------------------------------------------------

/// The CREATE statements of rosbag2's sqlite3 storage plugin, by distribution.
enum class Rosbag2Schema {
  kDashing,  ///< Dashing / Eloquent: topics without offered_qos_profiles, no schema table
  kFoxy,     ///< Foxy: offered_qos_profiles, no schema table
  kHumble,   ///< Humble: schema (version 3) and metadata tables
  kJazzy,    ///< Iron / Jazzy: type_description_hash and message_definitions
};

std::string CreateStatements(Rosbag2Schema schema) {
  const std::string schema_tables =
      "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);"
      "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
      "metadata TEXT NOT NULL);";
  const std::string messages =
      "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
      "timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
      "CREATE INDEX timestamp_idx ON messages (timestamp ASC);";
  const std::string topics =
      "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
      "serialization_format TEXT NOT NULL";
  switch (schema) {
    case Rosbag2Schema::kDashing:
      return topics + ");" + messages;
    case Rosbag2Schema::kFoxy:
      return topics + ",offered_qos_profiles TEXT NOT NULL);" + messages;
    case Rosbag2Schema::kHumble:
      return schema_tables + topics + ",offered_qos_profiles TEXT NOT NULL);" + messages +
             "INSERT INTO schema (schema_version, ros_distro) VALUES (3, 'humble');";
    case Rosbag2Schema::kJazzy:
      return schema_tables + topics +
             ",offered_qos_profiles TEXT NOT NULL,type_description_hash TEXT NOT NULL);"
             "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY,topic_type TEXT NOT NULL,"
             "encoding TEXT NOT NULL,encoded_message_definition TEXT NOT NULL,"
             "type_description_hash TEXT NOT NULL);" +
             messages + "INSERT INTO schema (schema_version, ros_distro) VALUES (4, 'jazzy');";
  }
  return {};
}

/// A .db3 file being written (closed on destruction).
class Db3Writer {
 public:
  /// An empty database at `path` with `sql` run in it.
  Db3Writer(const fs::path& path, const std::string& sql) {
    sqlite3* raw = nullptr;
    EXPECT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK) << path;
    db_.reset(raw);
    Exec(sql);
  }
  Db3Writer(const fs::path& path, Rosbag2Schema schema)
      : Db3Writer(path, CreateStatements(schema)) {
    schema_ = schema;
  }

  void Exec(const std::string& sql) {
    char* error = nullptr;
    EXPECT_EQ(sqlite3_exec(db_.get(), sql.c_str(), nullptr, nullptr, &error), SQLITE_OK)
        << sql << ": " << (error != nullptr ? error : "");
    sqlite3_free(error);
  }

  /// A row of topics as rosbag2 writes it.
  void Topic(int64_t id, const std::string& name, const std::string& type) {
    std::string columns = "id, name, type, serialization_format";
    std::string values = "?1, ?2, ?3, 'cdr'";
    if (schema_ != Rosbag2Schema::kDashing) {
      columns += ", offered_qos_profiles";
      values += ", ?4";
    }
    if (schema_ == Rosbag2Schema::kJazzy) {
      columns += ", type_description_hash";
      values += ", 'RIHS01_00'";
    }
    Statement s = Prepare("INSERT INTO topics (" + columns + ") VALUES (" + values + ")");
    sqlite3_bind_int64(s.get(), 1, id);
    sqlite3_bind_text(s.get(), 2, name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(s.get(), 3, type.c_str(), -1, SQLITE_TRANSIENT);
    const std::string qos = ros::mcap::OfferedQosProfiles();
    if (schema_ != Rosbag2Schema::kDashing) {
      sqlite3_bind_text(s.get(), 4, qos.c_str(), -1, SQLITE_TRANSIENT);
    }
    EXPECT_EQ(sqlite3_step(s.get()), SQLITE_DONE) << sqlite3_errmsg(db_.get());
  }

  /// A row of messages (its id: the next rowid), as rosbag2's INSERT writes it.
  void Message(int64_t topic_id, uint64_t timestamp, const std::vector<uint8_t>& data) {
    Statement s = Prepare("INSERT INTO messages (timestamp, topic_id, data) VALUES (?, ?, ?)");
    sqlite3_bind_int64(s.get(), 1, static_cast<int64_t>(timestamp));
    sqlite3_bind_int64(s.get(), 2, topic_id);
    // An empty vector's data() may be null, which would bind NULL.
    static const uint8_t kNone = 0;
    sqlite3_bind_blob(s.get(), 3, data.empty() ? &kNone : data.data(),
                      static_cast<int>(data.size()), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(s.get()), SQLITE_DONE) << sqlite3_errmsg(db_.get());
  }

 private:
  struct Closer {
    void operator()(sqlite3* db) const { sqlite3_close(db); }
  };
  struct Finalizer {
    void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
  };
  using Statement = std::unique_ptr<sqlite3_stmt, Finalizer>;

  Statement Prepare(const std::string& sql) {
    sqlite3_stmt* raw = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_.get(), sql.c_str(), -1, &raw, nullptr), SQLITE_OK)
        << sql << ": " << sqlite3_errmsg(db_.get());
    return Statement(raw);
  }

  std::unique_ptr<sqlite3, Closer> db_;
  Rosbag2Schema schema_ = Rosbag2Schema::kHumble;
};

std::vector<uint8_t> Chatter(const std::string& text) {
  return ros::msg::Encode(ros::msg::String{.data = text});
}

std::vector<uint8_t> Tf(const std::string& child, double x) {
  ros::msg::TransformStamped t;
  t.header.frame_id = "base_link";
  t.child_frame_id = child;
  t.transform.translation.x = x;
  return ros::msg::Encode(ros::msg::TFMessage{.transforms = {t}});
}

/// A String message `bytes` long (CDR included) with "<row i+1>" in its middle.
std::vector<uint8_t> LongPayload(int i, size_t bytes) {
  std::string text(bytes - 12, static_cast<char>('a' + i % 26));
  const std::string marker = "<row " + std::to_string(i + 1) + ">";
  text.replace(text.size() / 2, marker.size(), marker);
  return Chatter(text);
}

std::vector<uint8_t> Zstd(const std::vector<uint8_t>& in, bool record_size = true) {
  std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_contentSizeFlag, record_size ? 1 : 0);
  std::vector<uint8_t> out(ZSTD_compressBound(in.size()));
  const size_t n = ZSTD_compress2(cctx.get(), out.data(), out.size(), in.data(), in.size());
  EXPECT_EQ(ZSTD_isError(n), 0u);
  out.resize(n);
  return out;
}

/// Every message left, stopping at the first error (returned in `error`).
std::vector<BagMessage> ReadAll(MessageSource& source, Status* error = nullptr) {
  std::vector<BagMessage> out;
  for (;;) {
    Result<std::optional<BagMessage>> m = source.Next();
    if (!m.ok()) {
      if (error != nullptr) *error = m.status();
      return out;
    }
    if (!m->has_value()) return out;
    out.push_back(std::move(**m));
  }
}

class SqliteSourceTest : public test::TempDirTest {
 protected:
  /// A bag of two topics, its messages inserted out of time order (two at the same time).
  fs::path WriteTwoTopicBag(Rosbag2Schema schema, const std::string& name = "bag.db3") {
    const fs::path path = dir_ / name;
    Db3Writer w(path, schema);
    w.Topic(1, "/chatter", "std_msgs/msg/String");
    w.Topic(2, "/tf", "tf2_msgs/msg/TFMessage");
    w.Message(1, kT0 + 300, Chatter("third"));     // row 1
    w.Message(2, kT0 + 100, Tf("tool0", 0.5));     // row 2
    w.Message(1, kT0 + 200, Chatter("second a"));  // row 3
    w.Message(2, kT0 + 200, Tf("tool0", 0.7));     // row 4: ties with row 3
    w.Message(1, kT0 + 400, Chatter("fourth"));    // row 5
    return path;
  }

  /// The messages of WriteTwoTopicBag, checked.
  void ExpectTwoTopicMessages(MessageSource& source) {
    Status error;
    const std::vector<BagMessage> got = ReadAll(source, &error);
    ASSERT_TRUE(error.ok()) << error.ToString();
    ASSERT_EQ(got.size(), 5u);
    const std::vector<std::pair<std::string, uint64_t>> expected = {{"/tf", kT0 + 100},
                                                                    {"/chatter", kT0 + 200},
                                                                    {"/tf", kT0 + 200},
                                                                    {"/chatter", kT0 + 300},
                                                                    {"/chatter", kT0 + 400}};
    for (size_t i = 0; i < got.size(); ++i) {
      EXPECT_EQ(got[i].topic, expected[i].first) << i;
      EXPECT_EQ(got[i].log_time, expected[i].second) << i;
      EXPECT_EQ(got[i].encoding, "cdr") << i;
      EXPECT_EQ(got[i].type,
                got[i].topic == "/tf" ? "tf2_msgs/msg/TFMessage" : "std_msgs/msg/String");
    }
    EXPECT_EQ(got[0].data, Tf("tool0", 0.5));
    EXPECT_EQ(got[1].data, Chatter("second a"));
    EXPECT_EQ(got[2].data, Tf("tool0", 0.7));
    EXPECT_EQ(got[3].data, Chatter("third"));
    EXPECT_EQ(got[4].data, Chatter("fourth"));
    EXPECT_EQ(ros::msg::Decode<ros::msg::String>(got[4].data).value().data, "fourth");
    const ros::msg::TFMessage tf = ros::msg::Decode<ros::msg::TFMessage>(got[2].data).value();
    ASSERT_EQ(tf.transforms.size(), 1u);
    EXPECT_EQ(tf.transforms[0].transform.translation.x, 0.7);
  }
};

TEST_F(SqliteSourceTest, HumbleBagStreamsByTimestampWithExactBytes) {
  const fs::path path = WriteTwoTopicBag(Rosbag2Schema::kHumble);
  auto source = OpenSqliteSource(path).value();
  const BagInfo& info = source->info();
  EXPECT_EQ(info.format, "rosbag2 SQLite 3");
  EXPECT_THAT(info.files, ElementsAre(path));
  EXPECT_EQ(info.file_bytes, fs::file_size(path));
  EXPECT_THAT(info.topic_types, ElementsAre(Pair("/chatter", "std_msgs/msg/String"),
                                            Pair("/tf", "tf2_msgs/msg/TFMessage")));
  EXPECT_THAT(info.topic_counts, ElementsAre(Pair("/chatter", 3u), Pair("/tf", 2u)));
  EXPECT_TRUE(info.metadata.empty());
  EXPECT_EQ(source->bytes_read(), 0u);

  ExpectTwoTopicMessages(*source);
  EXPECT_EQ(source->bytes_read(), info.file_bytes);
  // At the end, Next keeps saying so.
  for (int i = 0; i < 2; ++i) {
    Result<std::optional<BagMessage>> end = source->Next();
    ASSERT_TRUE(end.ok());
    EXPECT_FALSE(end->has_value());
  }
}

TEST_F(SqliteSourceTest, FoxyDashingAndJazzySchemasRead) {
  for (Rosbag2Schema schema :
       {Rosbag2Schema::kDashing, Rosbag2Schema::kFoxy, Rosbag2Schema::kJazzy}) {
    SCOPED_TRACE(static_cast<int>(schema));
    const fs::path path =
        WriteTwoTopicBag(schema, "bag" + std::to_string(static_cast<int>(schema)) + ".db3");
    auto source = OpenSqliteSource(path).value();
    EXPECT_THAT(source->info().topic_counts, ElementsAre(Pair("/chatter", 3u), Pair("/tf", 2u)));
    ExpectTwoTopicMessages(*source);
  }
}

TEST_F(SqliteSourceTest, TopicWithoutMessagesCountsZeroAndEmptyMessageIsKept) {
  const fs::path path = dir_ / "bag.db3";
  {
    Db3Writer w(path, Rosbag2Schema::kHumble);
    w.Topic(1, "/chatter", "std_msgs/msg/String");
    w.Topic(7, "/rosout", "rcl_interfaces/msg/Log");
    w.Message(1, kT0, {});
  }
  auto source = OpenSqliteSource(path).value();
  EXPECT_THAT(source->info().topic_counts, ElementsAre(Pair("/chatter", 1u), Pair("/rosout", 0u)));
  const std::vector<BagMessage> got = ReadAll(*source);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_TRUE(got[0].data.empty());
  EXPECT_EQ(got[0].log_time, kT0);
}

TEST_F(SqliteSourceTest, PerMessageZstdDecompresses) {
  const fs::path path = dir_ / "bag.db3";
  const std::vector<uint8_t> big = Chatter(std::string(5000, 'x') + "end");
  {
    Db3Writer w(path, Rosbag2Schema::kHumble);
    w.Topic(1, "/chatter", "std_msgs/msg/String");
    w.Message(1, kT0 + 2, Zstd(big));
    w.Message(1, kT0 + 1, Zstd(Chatter("first")));
  }
  auto source = OpenSqliteSource(path, "zstd").value();
  EXPECT_THAT(source->info().format, HasSubstr("zstd"));
  const std::vector<BagMessage> got = ReadAll(*source);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].data, Chatter("first"));
  EXPECT_EQ(got[1].data, big);

  // The same file without the compression: the zstd frames as stored.
  auto raw = OpenSqliteSource(path, "").value();
  EXPECT_EQ(ReadAll(*raw)[1].data, Zstd(big));

  Result<std::unique_ptr<MessageSource>> lz4 = OpenSqliteSource(path, "lz4");
  ASSERT_FALSE(lz4.ok());
  EXPECT_EQ(lz4.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(lz4.status().message(), HasSubstr("'lz4'"));
}

TEST_F(SqliteSourceTest, ZstdErrorsNameTheRow) {
  const fs::path path = dir_ / "bag.db3";
  {
    Db3Writer w(path, Rosbag2Schema::kHumble);
    w.Topic(1, "/chatter", "std_msgs/msg/String");
    w.Message(1, kT0 + 1, Zstd(Chatter("ok")));
    w.Message(1, kT0 + 2, Chatter("not compressed"));        // row 2
    w.Message(1, kT0 + 3, Zstd(Chatter("no size"), false));  // row 3
  }
  auto source = OpenSqliteSource(path, "zstd").value();
  Status error;
  EXPECT_EQ(ReadAll(*source, &error).size(), 1u);
  EXPECT_THAT(error.message(), HasSubstr(path.string() + ": message row 2"));
  EXPECT_THAT(error.message(), HasSubstr("not a zstd frame"));
  EXPECT_THAT(error.message(), HasSubstr("the 1 message before it (up to row 1) were read"));

  // Without row 2, row 3's frame lacks its size.
  { Db3Writer w(path, "DELETE FROM messages WHERE id = 2;"); }
  source = OpenSqliteSource(path, "zstd").value();
  EXPECT_EQ(ReadAll(*source, &error).size(), 1u);
  EXPECT_THAT(error.message(), HasSubstr("message row 3"));
  EXPECT_THAT(error.message(), HasSubstr("does not record its decompressed size"));
}

TEST_F(SqliteSourceTest, UnknownTopicIdStopsAfterTheRowsBeforeIt) {
  const fs::path path = dir_ / "bag.db3";
  {
    Db3Writer w(path, Rosbag2Schema::kHumble);
    w.Topic(1, "/chatter", "std_msgs/msg/String");
    w.Message(1, kT0 + 1, Chatter("one"));
    w.Message(1, kT0 + 2, Chatter("two"));
    w.Message(99, kT0 + 3, Chatter("lost"));  // row 3
    w.Message(1, kT0 + 4, Chatter("after"));
  }
  auto source = OpenSqliteSource(path).value();
  // The unknown topic's message is not counted.
  EXPECT_THAT(source->info().topic_counts, ElementsAre(Pair("/chatter", 3u)));
  Status error;
  const std::vector<BagMessage> got = ReadAll(*source, &error);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].data, Chatter("one"));
  EXPECT_EQ(got[1].data, Chatter("two"));
  EXPECT_EQ(error.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(error.message(), StartsWith(path.string() + ": message row 3: its topic_id 99"));
  EXPECT_THAT(error.message(), HasSubstr("its ids: 1"));
  EXPECT_THAT(error.message(), HasSubstr("the 2 messages before it (up to row 2) were read"));
  // After the error, the same error.
  for (int i = 0; i < 2; ++i) {
    Result<std::optional<BagMessage>> again = source->Next();
    ASSERT_FALSE(again.ok());
    EXPECT_EQ(again.status(), error);
  }
}

TEST_F(SqliteSourceTest, NegativeTimestampAndNullDataAreErrors) {
  const fs::path path = dir_ / "foreign.db3";
  {
    // A writer other than rosbag2, without NOT NULL.
    Db3Writer w(path,
                "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT,"
                " serialization_format TEXT);"
                "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER,"
                " timestamp INTEGER, data BLOB);"
                "INSERT INTO topics VALUES (1, '/a', 'std_msgs/msg/String', 'cdr');"
                "INSERT INTO messages VALUES (1, 1, 5, x'00010000');"
                "INSERT INTO messages VALUES (2, 1, 6, NULL);"
                "INSERT INTO messages VALUES (3, 1, -7, x'00');");
  }
  auto source = OpenSqliteSource(path).value();
  Status error;
  EXPECT_TRUE(ReadAll(*source, &error).empty());
  EXPECT_THAT(error.message(), StartsWith(path.string() + ": message row 3"));
  EXPECT_THAT(error.message(), HasSubstr("timestamp -7 is negative"));
  EXPECT_THAT(error.message(), HasSubstr("no message before it was read"));

  { Db3Writer w(path, "DELETE FROM messages WHERE id = 3;"); }
  source = OpenSqliteSource(path).value();
  const std::vector<BagMessage> got = ReadAll(*source, &error);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].data, (std::vector<uint8_t>{0, 1, 0, 0}));
  EXPECT_THAT(error.message(), StartsWith(path.string() + ": message row 2"));
  EXPECT_THAT(error.message(), HasSubstr("its data is NULL (a message on '/a')"));
}

/// A Humble bag of `count` messages on /chatter, row i + 1 at kT0 + i, each `bytes` long with a
/// marker naming its row in the middle ("<row 17>").
fs::path WriteLongBag(const fs::path& path, int count, size_t bytes) {
  Db3Writer w(path, Rosbag2Schema::kHumble);
  w.Topic(1, "/chatter", "std_msgs/msg/String");
  w.Exec("BEGIN");
  for (int i = 0; i < count; ++i)
    w.Message(1, kT0 + static_cast<uint64_t>(i), LongPayload(i, bytes));
  w.Exec("COMMIT");
  return path;
}

TEST_F(SqliteSourceTest, TruncatedFileNamesTheFileAndWhereItStops) {
  constexpr int kCount = 400;
  const fs::path whole = WriteLongBag(dir_ / "whole.db3", kCount, 900);
  const uint64_t full = fs::file_size(whole);
  // Cut at 90%, the timestamp index (its pages written when its root first split, about 70% into
  // the file) is whole and the messages up to the cut come; cut at half, the index is lost too.
  for (const uint64_t cut : {full * 9 / 10, full / 2}) {
    SCOPED_TRACE(cut);
    const fs::path path = dir_ / ("cut_" + std::to_string(cut) + ".db3");
    fs::copy_file(whole, path);
    fs::resize_file(path, cut);
    // SQLite refuses such a file before reading anything; OpenSqliteSource reads what is there.
    auto source = OpenSqliteSource(path).value();
    EXPECT_EQ(source->info().file_bytes, cut);
    Status error;
    const std::vector<BagMessage> got = ReadAll(*source, &error);
    ASSERT_FALSE(error.ok());
    // Whatever comes is intact and in order.
    if (cut > full / 2) {
      EXPECT_GT(got.size(), 200u);
    } else {
      EXPECT_TRUE(got.empty());
    }
    EXPECT_LT(got.size(), static_cast<size_t>(kCount));
    for (size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].log_time, kT0 + i);
      ASSERT_EQ(got[i].data, LongPayload(static_cast<int>(i), 900));
    }
    EXPECT_EQ(error.code(), StatusCode::kParseError);
    EXPECT_THAT(error.message(), StartsWith(path.string() + ": SQLite stops reading"));
    EXPECT_THAT(error.message(),
                HasSubstr(fmt::format("the file is truncated: {} of the {} bytes its header gives",
                                      cut, full)));
    EXPECT_THAT(error.message(),
                HasSubstr(got.empty() ? std::string("no message before it was read")
                                      : fmt::format("the {} messages before it (up to row {}) "
                                                    "were read",
                                                    got.size(), got.size())));
    EXPECT_LE(source->bytes_read(), cut);
    Result<std::optional<BagMessage>> again = source->Next();
    ASSERT_FALSE(again.ok());
    EXPECT_EQ(again.status(), error);
  }
}

TEST_F(SqliteSourceTest, CorruptRowMidStreamDeliversTheRowsBeforeIt) {
  constexpr int kCount = 40;
  constexpr size_t kBytes = 12000;  // past SQLite's 4 KiB page: the data spans overflow pages
  const fs::path path = WriteLongBag(dir_ / "bag.db3", kCount, kBytes);
  // Row 26's marker lies on an overflow page, whose first 4 bytes link the next one: point them
  // past the end of the database.
  std::string bytes = test::ReadWholeFile(path);
  const size_t marker = bytes.find("<row 26>");
  ASSERT_NE(marker, std::string::npos);
  const size_t page = marker - marker % 4096;
  bytes.replace(page, 4, "\x7f\xff\xff\xff");
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;

  auto source = OpenSqliteSource(path).value();
  Status error;
  const std::vector<BagMessage> got = ReadAll(*source, &error);
  ASSERT_EQ(got.size(), 25u);
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].data, LongPayload(static_cast<int>(i), kBytes)) << i;
  }
  EXPECT_EQ(error.code(), StatusCode::kParseError);
  EXPECT_THAT(error.message(), StartsWith(path.string() + ": SQLite stops reading at message "
                                                          "row 26: database disk image is "
                                                          "malformed (the file is damaged or "
                                                          "truncated); the 25 messages before it "
                                                          "(up to row 25) were read"));
  EXPECT_EQ(source->bytes_read(), 25 * (kBytes - 3));  // the data sizes
  Result<std::optional<BagMessage>> again = source->Next();
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status(), error);
}

TEST_F(SqliteSourceTest, ForeignFilesAreNamed) {
  // An MCAP named .db3.
  const fs::path mcap = dir_ / "recording.db3";
  {
    auto w = ros::mcap::Writer::Open(mcap).value();
    const uint16_t schema = w->AddSchema("std_msgs/msg/String", "ros2msg", "string data").value();
    const uint16_t channel = w->AddChannel(schema, "/chatter", "cdr").value();
    ASSERT_TRUE(w->Write(channel, 0, kT0, kT0, Chatter("hi")).ok());
    ASSERT_TRUE(w->Close().ok());
  }
  Result<std::unique_ptr<MessageSource>> r = OpenSqliteSource(mcap);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), StartsWith(mcap.string() + ": not an SQLite database"));
  EXPECT_THAT(r.status().message(), HasSubstr("an MCAP recording; open it as an MCAP bag"));

  const fs::path png = Write("image.db3", std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16));
  r = OpenSqliteSource(png);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), StartsWith(png.string() + ": not an SQLite database"));
  EXPECT_THAT(r.status().message(), HasSubstr("it is a PNG image"));

  const fs::path empty = Write("empty.db3", "");
  r = OpenSqliteSource(empty);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), StartsWith(empty.string() + ": the file is empty"));

  r = OpenSqliteSource(dir_ / "missing.db3");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), HasSubstr("missing.db3"));
}

TEST_F(SqliteSourceTest, SqliteWithoutRosbag2TablesNamesItsTables) {
  const fs::path path = dir_ / "other.db3";
  {
    Db3Writer w(path,
                "CREATE TABLE photos(id INTEGER PRIMARY KEY, data BLOB);"
                "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT,"
                " serialization_format TEXT);");
  }
  Result<std::unique_ptr<MessageSource>> r = OpenSqliteSource(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(),
              StartsWith(path.string() + ": an SQLite database but not a rosbag2 bag: it has no "
                                         "messages table (its tables: 'photos', 'topics'"));

  const fs::path empty = dir_ / "empty_db.db3";
  { Db3Writer w(empty, "CREATE TABLE t(x); DROP TABLE t;"); }
  r = OpenSqliteSource(empty);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("no topics or messages tables"));
  EXPECT_THAT(r.status().message(), HasSubstr("it has no tables at all"));
}

// ---- metadata.yaml ------------------------------------------------------------------------------

class BagFolderTest : public test::TempDirTest {
 protected:
  /// Humble's metadata.yaml (version 5) of a bag split over `files`.
  static std::string HumbleMetadata(const std::vector<std::string>& files,
                                    const std::string& storage = "sqlite3",
                                    const std::string& mode = "", const std::string& format = "") {
    std::string paths;
    std::string file_entries;
    for (const std::string& f : files) {
      paths += "    - " + f + "\n";
      file_entries += "    - path: " + f +
                      "\n      starting_time:\n        nanoseconds_since_epoch: 1690000000000000000"
                      "\n      duration:\n        nanoseconds: 100\n      message_count: 2\n";
    }
    return "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: " + storage +
           "\n  relative_file_paths:\n" + paths +
           "  duration:\n    nanoseconds: 9500166674\n"
           "  starting_time:\n    nanoseconds_since_epoch: 1690000000000000000\n"
           "  message_count: 5\n"
           "  topics_with_message_count:\n"
           "    - topic_metadata:\n"
           "        name: /chatter\n"
           "        type: std_msgs/msg/String\n"
           "        serialization_format: cdr\n"
           "        offered_qos_profiles: \"- history: 3\\n  depth: 0\\n  reliability: 1\\n"
           "  durability: 2\\n  avoid_ros_namespace_conventions: false\"\n"
           "      message_count: 3\n"
           "    - topic_metadata:\n"
           "        name: /tf\n"
           "        type: tf2_msgs/msg/TFMessage\n"
           "        serialization_format: cdr\n"
           "        offered_qos_profiles: \"\"\n"
           "      message_count: 2\n"
           "  compression_format: \"" +
           format + "\"\n  compression_mode: \"" + mode + "\"\n  files:\n" + file_entries;
  }

  /// The error of ReadBagFolderMetadata(dir_) with `yaml` as metadata.yaml.
  Status ErrorFor(const std::string& yaml) {
    Write("metadata.yaml", yaml);
    Result<BagFolderMetadata> r = ReadBagFolderMetadata(dir_);
    EXPECT_FALSE(r.ok()) << yaml;
    return r.status();
  }

  std::string MetadataPath() const { return (dir_ / "metadata.yaml").string(); }
};

TEST_F(BagFolderTest, HumbleSplitBagListsBothFilesInOrder) {
  const std::string f0 = "rosbag2_2024_01_01-00_00_00_0.db3";
  const std::string f1 = "rosbag2_2024_01_01-00_00_00_1.db3";
  {
    Db3Writer a(dir_ / f0, Rosbag2Schema::kHumble);
    a.Topic(1, "/chatter", "std_msgs/msg/String");
    a.Message(1, kT0 + 1, Chatter("in file 0"));
    Db3Writer b(dir_ / f1, Rosbag2Schema::kHumble);
    b.Topic(1, "/chatter", "std_msgs/msg/String");
    b.Message(1, kT0 + 2, Chatter("in file 1"));
  }
  Write("metadata.yaml", HumbleMetadata({f0, f1}));

  const BagFolderMetadata m = ReadBagFolderMetadata(dir_).value();
  EXPECT_EQ(m.version, 5);
  EXPECT_EQ(m.storage_identifier, "sqlite3");
  const fs::path folder = fs::absolute(dir_);
  EXPECT_THAT(m.files, ElementsAre(folder / f0, folder / f1));
  EXPECT_TRUE(m.files[0].is_absolute());
  EXPECT_THAT(m.topic_types, ElementsAre(Pair("/chatter", "std_msgs/msg/String"),
                                         Pair("/tf", "tf2_msgs/msg/TFMessage")));
  EXPECT_THAT(m.topic_counts, ElementsAre(Pair("/chatter", 3u), Pair("/tf", 2u)));
  EXPECT_EQ(m.compression_mode, "");
  EXPECT_EQ(m.compression_format, "");

  // The files it names are the bag's .db3 files.
  EXPECT_EQ(ReadAll(*OpenSqliteSource(m.files[1]).value())[0].data, Chatter("in file 1"));

  // A trailing separator on the folder makes no difference.
  const BagFolderMetadata again = ReadBagFolderMetadata(dir_.string() + "/").value();
  EXPECT_EQ(again.files, m.files);
}

TEST_F(BagFolderTest, JazzyMcapMetadataReads) {
  Write("bag_0.mcap", "\x89MCAP0\r\n");
  Write("metadata.yaml",
        "rosbag2_bagfile_information:\n"
        "  version: 9\n"
        "  storage_identifier: mcap\n"
        "  duration: {nanoseconds: 10}\n"
        "  starting_time: {nanoseconds_since_epoch: 1690000000000000000}\n"
        "  message_count: 4\n"
        "  topics_with_message_count:\n"
        "    - topic_metadata:\n"
        "        name: /joint_states\n"
        "        type: sensor_msgs/msg/JointState\n"
        "        serialization_format: cdr\n"
        "        offered_qos_profiles:\n"
        "          - history: keep_last\n"
        "            depth: 10\n"
        "            reliability: reliable\n"
        "        type_description_hash: RIHS01_abc\n"
        "      message_count: 4\n"
        "  compression_format: \"\"\n"
        "  compression_mode: \"\"\n"
        "  relative_file_paths: [bag_0.mcap]\n"
        "  files:\n"
        "    - {path: bag_0.mcap, starting_time: {nanoseconds_since_epoch: 1}, duration: "
        "{nanoseconds: 10}, message_count: 4}\n"
        "  custom_data: ~\n"
        "  ros_distro: jazzy\n");
  const BagFolderMetadata jazzy = ReadBagFolderMetadata(dir_).value();
  EXPECT_EQ(jazzy.version, 9);
  EXPECT_EQ(jazzy.storage_identifier, "mcap");
  EXPECT_THAT(jazzy.files, ElementsAre(fs::absolute(dir_) / "bag_0.mcap"));
  EXPECT_THAT(jazzy.topic_counts, ElementsAre(Pair("/joint_states", 4u)));
}

TEST_F(BagFolderTest, OlderPathsPrefixedWithTheFolderNameResolve) {
  const fs::path folder = dir_ / "old_bag";
  fs::create_directories(folder);
  std::ofstream(folder / "old_bag_0.db3") << "x";
  std::ofstream(folder / "metadata.yaml")
      << "rosbag2_bagfile_information:\n  version: 3\n  storage_identifier: sqlite3\n"
         "  relative_file_paths: [old_bag/old_bag_0.db3]\n";
  const BagFolderMetadata m = ReadBagFolderMetadata(folder).value();
  EXPECT_EQ(m.version, 3);
  EXPECT_THAT(m.files, ElementsAre(fs::absolute(folder) / "old_bag_0.db3"));
  EXPECT_TRUE(m.topic_types.empty());
}

TEST_F(BagFolderTest, MessageCompressionIsRecordedFileCompressionRefused) {
  Write("b_0.db3", "x");
  Write("metadata.yaml", HumbleMetadata({"b_0.db3"}, "sqlite3", "MESSAGE", "zstd"));
  BagFolderMetadata m = ReadBagFolderMetadata(dir_).value();
  EXPECT_EQ(m.compression_mode, "MESSAGE");
  EXPECT_EQ(m.compression_format, "zstd");
  Write("metadata.yaml", HumbleMetadata({"b_0.db3"}, "sqlite3", "none", "zstd"));
  m = ReadBagFolderMetadata(dir_).value();
  EXPECT_EQ(m.compression_mode, "");
  EXPECT_EQ(m.compression_format, "");

  Write("b_0.db3.zstd", "x");
  Status e = ErrorFor(HumbleMetadata({"b_0.db3.zstd"}, "sqlite3", "FILE", "zstd"));
  EXPECT_EQ(e.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(e.message(), StartsWith("'" + MetadataPath() +
                                      "': rosbag2_bagfile_information: "
                                      "'compression_mode' is FILE"));
  EXPECT_THAT(e.message(), HasSubstr("compressed whole"));
  EXPECT_THAT(e.message(), HasSubstr("`zstd -d FILE`"));
  EXPECT_THAT(e.message(), HasSubstr("`ros2 bag convert -i BAG -o out.yaml`"));

  e = ErrorFor(HumbleMetadata({"b_0.db3"}, "sqlite3", "MESSAGE", "lz4"));
  EXPECT_THAT(e.message(), HasSubstr("'compression_format' is 'lz4'"));
  e = ErrorFor(HumbleMetadata({"b_0.db3"}, "sqlite3", "CHUNK", ""));
  EXPECT_THAT(e.message(), HasSubstr("'compression_mode' is 'CHUNK'"));
}

TEST_F(BagFolderTest, MissingFolderOrMetadataFile) {
  Result<BagFolderMetadata> r = ReadBagFolderMetadata(dir_ / "nowhere");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), HasSubstr((dir_ / "nowhere").string()));

  Write("bag_0.db3", "x");
  r = ReadBagFolderMetadata(dir_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(r.status().message(), StartsWith("'" + MetadataPath() + "' does not exist"));
  EXPECT_THAT(r.status().message(), HasSubstr("it holds 'bag_0.db3'"));
  EXPECT_THAT(r.status().message(), HasSubstr("ros2 bag reindex"));

  r = ReadBagFolderMetadata(dir_ / "bag_0.db3");
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.status().message(), HasSubstr("is not a folder"));
}

TEST_F(BagFolderTest, NotYamlOrNotRosbag2) {
  Status e = ErrorFor(std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16));
  EXPECT_THAT(e.message(), HasSubstr(MetadataPath()));
  EXPECT_THAT(e.message(), HasSubstr("a PNG image"));

  e = ErrorFor("rosbag2_bagfile_information: [unclosed\n");
  EXPECT_EQ(e.code(), StatusCode::kParseError);
  EXPECT_THAT(e.message(), HasSubstr(MetadataPath()));

  e = ErrorFor("output_bags:\n  - uri: x\n");
  EXPECT_THAT(e.message(),
              StartsWith("'" + MetadataPath() + "': no 'rosbag2_bagfile_information' map"));
  EXPECT_THAT(e.message(), HasSubstr("its top-level keys: 'output_bags'"));

  e = ErrorFor("rosbag2_bagfile_information:\n  version: 5\n  version: 6\n");
  EXPECT_THAT(e.message(), HasSubstr(MetadataPath()));
  EXPECT_THAT(e.message(), HasSubstr("version"));
}

TEST_F(BagFolderTest, KeyErrorsNameTheFileAndTheKey) {
  Write("a.db3", "x");
  const std::string context = "'" + MetadataPath() + "': rosbag2_bagfile_information: ";

  Status e = ErrorFor("rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n");
  EXPECT_THAT(e.message(), StartsWith(context + "'version' is missing"));

  e = ErrorFor(HumbleMetadata({"a.db3"}, "rosbag_v2"));
  EXPECT_THAT(e.message(), StartsWith(context + "'storage_identifier' is 'rosbag_v2'"));
  EXPECT_THAT(e.message(), HasSubstr("sqlite3"));
  EXPECT_THAT(e.message(), HasSubstr("mcap"));

  e = ErrorFor("rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n");
  EXPECT_THAT(e.message(), StartsWith(context + "'relative_file_paths' is missing"));
  EXPECT_THAT(e.message(), HasSubstr("'a.db3'"));

  e = ErrorFor(
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
      "  relative_file_paths: []\n");
  EXPECT_THAT(e.message(), StartsWith(context + "'relative_file_paths' is empty"));

  e = ErrorFor(HumbleMetadata({"/etc/passwd"}));
  EXPECT_THAT(e.message(), StartsWith(context + "relative_file_paths[0] is '/etc/passwd'"));
  EXPECT_THAT(e.message(), HasSubstr("a relative path"));

  e = ErrorFor(HumbleMetadata({"a.db3", "../other/a.db3"}));
  EXPECT_THAT(e.message(), StartsWith(context + "relative_file_paths[1] is '../other/a.db3'"));
  EXPECT_THAT(e.message(), HasSubstr("would leave the bag folder"));

  e = ErrorFor(HumbleMetadata({"a.db3", "sub/../a.db3"}));
  EXPECT_THAT(e.message(), HasSubstr("'..' would leave the bag folder"));

  e = ErrorFor(HumbleMetadata({"a.db3", "b.db3"}));
  EXPECT_EQ(e.code(), StatusCode::kNotFound);
  EXPECT_THAT(e.message(), StartsWith(context + "relative_file_paths[1]: 'b.db3' does not exist "
                                                "in the bag folder (it holds 'a.db3', "
                                                "'metadata.yaml')"));

  e = ErrorFor(
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
      "  relative_file_paths: [a.db3]\n  topics_with_message_count:\n"
      "    - topic_metadata: {name: /a, type: std_msgs/msg/String}\n      message_count: -1\n");
  EXPECT_THAT(e.message(),
              StartsWith(context + "topics_with_message_count[0]: 'message_count' is -1"));
}

}  // namespace
}  // namespace avp::ros::bag
