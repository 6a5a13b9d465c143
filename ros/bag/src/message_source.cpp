// Bags as one stream of messages in log-time order: MCAP files (through ros::mcap::StreamReader),
// split bags merged, and the dispatch by what a path holds (message_source.h).
#include <algorithm>
#include <fstream>
#include <set>
#include <system_error>
#include <utility>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file_kind.h>
#include <avp/ros/bag/message_source.h>
#include <avp/ros/mcap/mcap.h>

namespace avp::ros::bag {

namespace fs = std::filesystem;

namespace {

class McapSource final : public MessageSource {
 public:
  explicit McapSource(std::unique_ptr<ros::mcap::StreamReader> reader)
      : reader_(std::move(reader)) {
    const ros::mcap::File& f = reader_->info();
    info_.format = fmt::format(
        "MCAP ({}{})", reader_->indexed() ? "indexed" : "streaming: no usable summary",
        reader_->chunk_compression().empty() ? ""
                                             : ", " + reader_->chunk_compression() + " chunks");
    info_.files = {reader_->path()};
    info_.file_bytes = reader_->file_bytes();
    for (const ros::mcap::Metadata& m : f.metadata) info_.metadata[m.name] = m.metadata;
    for (const ros::mcap::Attachment& a : f.attachments) {
      info_.attachments.push_back({a.name, a.media_type, a.data});
    }
    LearnChannels();
    for (const auto& [channel, count] : f.statistics.channel_message_counts) {
      if (auto it = channels_.find(channel); it != channels_.end()) {
        info_.topic_counts[it->second.topic] += count;
      }
    }
  }

  const BagInfo& info() const override { return info_; }
  uint64_t bytes_read() const override { return reader_->bytes_read(); }

  Result<std::optional<BagMessage>> Next() override {
    AVP_ASSIGN_OR_RETURN(std::optional<ros::mcap::Message> m, reader_->Next());
    if (!m) return std::optional<BagMessage>();
    auto it = channels_.find(m->channel_id);
    if (it == channels_.end()) {
      LearnChannels();  // a streaming pass meets channels as it goes
      it = channels_.find(m->channel_id);
    }
    BagMessage out;
    if (it != channels_.end()) {
      out.topic = it->second.topic;
      out.type = it->second.type;
      out.encoding = it->second.encoding;
    } else {
      // The spec requires the channel before its messages; name the id rather than drop it.
      out.topic = fmt::format("(unknown channel {})", m->channel_id);
    }
    out.log_time = m->log_time;
    out.data = std::move(m->data);
    return std::optional<BagMessage>(std::move(out));
  }

 private:
  struct ChannelInfo {
    std::string topic, type, encoding;
  };

  void LearnChannels() {
    const ros::mcap::File& f = reader_->info();
    std::map<uint16_t, std::string> schemas;
    for (const ros::mcap::Schema& s : f.schemas) schemas[s.id] = s.name;
    for (const ros::mcap::Channel& c : f.channels) {
      if (channels_.contains(c.id)) continue;
      const auto s = schemas.find(c.schema_id);
      ChannelInfo ch{c.topic, s == schemas.end() ? std::string() : s->second, c.message_encoding};
      info_.topic_types.emplace(ch.topic, ch.type);
      channels_.emplace(c.id, std::move(ch));
    }
  }

  std::unique_ptr<ros::mcap::StreamReader> reader_;
  BagInfo info_;
  std::map<uint16_t, ChannelInfo> channels_;
};

/// Several sources in log-time order: the head message of each, the earliest delivered first.
class MergedSource final : public MessageSource {
 public:
  MergedSource(std::vector<std::unique_ptr<MessageSource>> sources, std::string format)
      : sources_(std::move(sources)), heads_(sources_.size()) {
    info_.format = std::move(format);
    for (const auto& s : sources_) {
      const BagInfo& i = s->info();
      info_.files.insert(info_.files.end(), i.files.begin(), i.files.end());
      info_.file_bytes += i.file_bytes;
      for (const auto& [name, m] : i.metadata) info_.metadata.emplace(name, m);
      info_.attachments.insert(info_.attachments.end(), i.attachments.begin(), i.attachments.end());
      for (const auto& [topic, type] : i.topic_types) info_.topic_types.emplace(topic, type);
      for (const auto& [topic, n] : i.topic_counts) info_.topic_counts[topic] += n;
    }
  }

  const BagInfo& info() const override { return info_; }

  uint64_t bytes_read() const override {
    uint64_t n = 0;
    for (const auto& s : sources_) n += s->bytes_read();
    return n;
  }

  Result<std::optional<BagMessage>> Next() override {
    if (!error_.ok()) return error_;
    size_t best = heads_.size();
    for (size_t i = 0; i < heads_.size(); ++i) {
      if (!heads_[i] && !ended_.contains(i)) {
        Result<std::optional<BagMessage>> m = sources_[i]->Next();
        if (!m.ok()) {
          // The messages before the damage were delivered; later files are not read (their
          // messages would come after it in time).
          error_ = m.status();
          return error_;
        }
        if (!*m) {
          ended_.insert(i);
          continue;
        }
        heads_[i] = std::move(*m);
      }
      if (heads_[i] && (best == heads_.size() || heads_[i]->log_time < heads_[best]->log_time)) {
        best = i;
      }
    }
    if (best == heads_.size()) return std::optional<BagMessage>();
    std::optional<BagMessage> out = std::move(heads_[best]);
    heads_[best].reset();
    return out;
  }

 private:
  std::vector<std::unique_ptr<MessageSource>> sources_;
  std::vector<std::optional<BagMessage>> heads_;
  std::set<size_t> ended_;
  Status error_;
  BagInfo info_;
};

/// What `path` holds, for the error when it is not a bag.
std::string Describe(const fs::path& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return "a folder without metadata.yaml, .mcap or .db3 files";
  std::ifstream in(path, std::ios::binary);
  std::string head(64, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(std::max<std::streamsize>(in.gcount(), 0)));
  const std::string kind = io::DescribeFileKind(head);
  return kind.empty() ? "not MCAP, not SQLite" : kind;
}

/// A folder's bag files without metadata.yaml: its .mcap files, else its .db3 files, by name.
std::vector<fs::path> BagFilesIn(const fs::path& folder, std::string& storage) {
  std::vector<fs::path> mcap, db3;
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(folder, ec)) {
    if (!e.is_regular_file(ec)) continue;
    if (e.path().extension() == ".mcap") mcap.push_back(e.path());
    if (e.path().extension() == ".db3") db3.push_back(e.path());
  }
  std::sort(mcap.begin(), mcap.end());
  std::sort(db3.begin(), db3.end());
  storage = mcap.empty() ? "sqlite3" : "mcap";
  return mcap.empty() ? db3 : mcap;
}

Result<std::unique_ptr<MessageSource>> OpenFolder(const fs::path& folder) {
  BagFolderMetadata meta;
  std::error_code ec;
  if (fs::exists(folder / "metadata.yaml", ec)) {
    AVP_ASSIGN_OR_RETURN(meta, ReadBagFolderMetadata(folder));
  } else {
    meta.files = BagFilesIn(folder, meta.storage_identifier);
    if (meta.files.empty()) {
      return NotFoundError(
          fmt::format("{}: {}: give a bag folder (metadata.yaml and its files), an .mcap or a "
                      ".db3 file",
                      folder.string(), Describe(folder)));
    }
  }
  std::vector<std::unique_ptr<MessageSource>> sources;
  for (const fs::path& f : meta.files) {
    Result<std::unique_ptr<MessageSource>> s =
        meta.storage_identifier == "mcap"
            ? OpenMcapSource(f)
            : OpenSqliteSource(
                  f, meta.compression_mode == "MESSAGE" ? meta.compression_format : std::string());
    if (!s.ok()) return s.status().WithContext(fmt::format("bag folder {}", folder.string()));
    sources.push_back(std::move(*s));
  }
  const std::string format = fmt::format("rosbag2 folder: {} {} file{}", sources.size(),
                                         meta.storage_identifier == "mcap" ? "MCAP" : "SQLite 3",
                                         sources.size() == 1 ? "" : "s");
  return MergeSources(std::move(sources), format);
}

bool StartsWith(const fs::path& path, std::string_view prefix) {
  std::ifstream in(path, std::ios::binary);
  std::string head(prefix.size(), '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  return in.gcount() == static_cast<std::streamsize>(head.size()) && head == prefix;
}

}  // namespace

Result<std::unique_ptr<MessageSource>> OpenMcapSource(const fs::path& file) {
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<ros::mcap::StreamReader> reader,
                       ros::mcap::StreamReader::Open(file));
  return std::unique_ptr<MessageSource>(std::make_unique<McapSource>(std::move(reader)));
}

std::unique_ptr<MessageSource> MergeSources(std::vector<std::unique_ptr<MessageSource>> sources,
                                            std::string format) {
  return std::make_unique<MergedSource>(std::move(sources), std::move(format));
}

Result<std::unique_ptr<MessageSource>> OpenBag(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    return NotFoundError(fmt::format("bag {} does not exist", QuoteText(path.string())));
  }
  if (fs::is_directory(path, ec)) return OpenFolder(path);
  if (StartsWith(path, "SQLite format 3")) return OpenSqliteSource(path);
  if (StartsWith(path, ros::mcap::kMagic) || path.extension() == ".mcap") {
    return OpenMcapSource(path);
  }
  return InvalidArgumentError(fmt::format(
      "{}: not a bag ({}): avp replay reads MCAP files, rosbag2 SQLite 3 (.db3) files and bag "
      "folders",
      path.string(), Describe(path)));
}

}  // namespace avp::ros::bag
