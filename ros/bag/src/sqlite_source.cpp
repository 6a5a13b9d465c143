// A rosbag2 SQLite 3 file (.db3) as a MessageSource: rosbag2's sqlite3 storage plugin (Dashing to
// Jazzy; Humble's default storage). The tables it reads:
//   topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, ...)
//   messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB)
// Other columns (offered_qos_profiles since Foxy, type_description_hash since Iron) and tables
// (schema, metadata, message_definitions) are not needed and may be absent.
//
// Bounded memory: the message order comes from one statement over (timestamp, id) only, which
// rosbag2's timestamp_idx index answers without sorting (a bag without that index: SQLite sorts
// these 16-byte pairs, spilling to a temporary file), and each message's row is then fetched by id:
// nothing holds more than the current row.
//
// Damage: a row SQLite cannot read ends the stream with an error naming the file and the last good
// row, after the rows before it. A truncated file (a recording killed mid-write) is read as far as
// its surviving pages go: SQLite itself refuses a file shorter than its header says, so that check
// is lifted for the (read-only) connection.

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <limits>
#include <span>
#include <string_view>
#include <utility>

#include <fmt/format.h>
#include <sqlite3.h>
#include <zstd.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/ros/bag/message_source.h>

namespace avp::ros::bag {
namespace {

namespace fs = std::filesystem;

struct DatabaseCloser {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};
struct StatementFinalizer {
  void operator()(sqlite3_stmt* statement) const { sqlite3_finalize(statement); }
};
/// An open database; closed on destruction (after its statements: declare them later).
using Database = std::unique_ptr<sqlite3, DatabaseCloser>;
/// A prepared statement; finalized on destruction.
using Statement = std::unique_ptr<sqlite3_stmt, StatementFinalizer>;

/// Every SQLite 3 database starts with these 16 bytes (the NUL included).
constexpr std::string_view kSqliteMagic("SQLite format 3\0", 16);
/// At most this many names (tables, topic ids) in a message.
constexpr size_t kMaxListed = 20;
/// What rosbag2 writes, for messages about a database that lacks it.
constexpr std::string_view kRosbag2Tables =
    "rosbag2 writes topics(id, name, type, serialization_format, ...) and messages(id, topic_id, "
    "timestamp, data)";

/// One row of the topics table.
struct TopicRow {
  std::string name;
  std::string type;
  std::string serialization_format;
};
using TopicsById = std::map<int64_t, TopicRow>;

/// SQLite's message for the last failure on `db` (escaped: it may quote the file's contents).
std::string SqliteMessage(sqlite3* db, int rc) {
  const char* text = db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  return EscapeText(text != nullptr ? text : sqlite3_errstr(rc), 200);
}

/// A column's text; "" for NULL.
std::string ColumnText(sqlite3_stmt* statement, int column) {
  const unsigned char* text = sqlite3_column_text(statement, column);
  if (text == nullptr) return {};
  return {reinterpret_cast<const char*>(text),
          static_cast<size_t>(sqlite3_column_bytes(statement, column))};
}

/// The first bytes of `file` (SQLite's 100-byte header) when it starts as an SQLite database
/// does; otherwise an error that says what the file is instead.
Result<std::string> ReadSqliteHeader(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    return IoError(fmt::format("{}: cannot be opened: {}", file.string(), std::strerror(errno)));
  }
  std::string head(512, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  if (head.size() >= 100 && head.starts_with(kSqliteMagic)) return head;
  if (head.empty() || (head.size() < 100 && head.starts_with(kSqliteMagic))) {
    return InvalidArgumentError(fmt::format(
        "{}: the file is {}, not a rosbag2 SQLite 3 bag (a .db3 file starts with SQLite's "
        "100-byte header 'SQLite format 3')",
        file.string(), head.empty() ? "empty" : fmt::format("only {} bytes", head.size())));
  }
  std::string kind = io::DescribeFileKind(head);
  const bool mcap = kind == "an MCAP recording";
  if (kind.empty()) kind = "text that avp does not recognise";
  return InvalidArgumentError(fmt::format(
      "{}: not an SQLite database, so not a rosbag2 .db3 bag (those start with 'SQLite format "
      "3'): it is {}{}",
      file.string(), kind, mcap ? "; open it as an MCAP bag (a .mcap file)" : ""));
}

/// The size SQLite's header gives the database (page size x page count), or 0 when the header
/// does not vouch for its page count (then SQLite goes by the file's size).
uint64_t HeaderDatabaseBytes(std::string_view header) {
  auto be32 = [&](size_t at) {
    uint32_t v = 0;
    for (size_t i = 0; i < 4; ++i) v = (v << 8) | static_cast<uint8_t>(header[at + i]);
    return v;
  };
  const uint32_t page_size = (static_cast<uint32_t>(static_cast<uint8_t>(header[16])) << 8) |
                             static_cast<uint8_t>(header[17]);
  // The page count is valid when the change counter (24) equals "version-valid-for" (92).
  if (be32(24) != be32(92)) return 0;
  return uint64_t{page_size == 1 ? 65536u : page_size} * be32(28);
}

Result<Database> OpenDatabase(const fs::path& file) {
  // An absolute path is never taken for a "file:" URI.
  const std::string name = fs::absolute(file).string();
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(name.c_str(), &raw, SQLITE_OPEN_READONLY, nullptr);
  Database db(raw);
  if (rc != SQLITE_OK) {
    return IoError(fmt::format("{}: SQLite cannot open it read-only: {}", file.string(),
                               SqliteMessage(db.get(), rc)));
  }
  // A bag still being recorded may hold a lock for a moment.
  sqlite3_busy_timeout(db.get(), 2000);
  return db;
}

/// Prepares `sql`; the error says what SQLite found wrong, in `what` ("reading its topics").
Result<Statement> Prepare(sqlite3* db, std::string_view sql, const fs::path& file,
                          std::string_view what) {
  sqlite3_stmt* raw = nullptr;
  const int rc = sqlite3_prepare_v2(db, sql.data(), static_cast<int>(sql.size()), &raw, nullptr);
  Statement statement(raw);
  if (rc != SQLITE_OK) {
    return ParseError(fmt::format("{}: {}: SQLite says {} ({})", file.string(), what,
                                  SqliteMessage(db, rc), kRosbag2Tables));
  }
  return statement;
}

/// The error for a failed sqlite3_step while `what`.
Status StepError(sqlite3* db, int rc, const fs::path& file, std::string_view what) {
  const bool damaged = rc == SQLITE_CORRUPT || rc == SQLITE_NOTADB;
  return ParseError(fmt::format("{}: {}: SQLite says {}{}", file.string(), what,
                                SqliteMessage(db, rc),
                                damaged ? " (the file is damaged or truncated)" : ""));
}

/// The names of the database's tables, sorted.
Result<std::vector<std::string>> TableNames(sqlite3* db, const fs::path& file) {
  constexpr std::string_view kWhat = "reading its list of tables";
  AVP_ASSIGN_OR_RETURN(
      Statement s, Prepare(db, "SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name",
                           file, kWhat));
  std::vector<std::string> names;
  int rc = SQLITE_ROW;
  while ((rc = sqlite3_step(s.get())) == SQLITE_ROW) names.push_back(ColumnText(s.get(), 0));
  if (rc != SQLITE_DONE) return StepError(db, rc, file, kWhat);
  return names;
}

/// OK when the database has rosbag2's topics and messages tables; else names those it has.
Status CheckRosbag2Tables(sqlite3* db, const fs::path& file) {
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> tables, TableNames(db, file));
  std::vector<std::string> missing;
  for (std::string_view need : {"topics", "messages"}) {
    if (std::find(tables.begin(), tables.end(), need) == tables.end()) {
      missing.emplace_back(need);
    }
  }
  if (missing.empty()) return Status::Ok();
  std::vector<std::string> quoted;
  for (const std::string& t : tables) {
    if (quoted.size() == kMaxListed) {
      quoted.push_back(fmt::format("{} more", tables.size() - kMaxListed));
      break;
    }
    quoted.push_back(QuoteText(t));
  }
  return InvalidArgumentError(
      fmt::format("{}: an SQLite database but not a rosbag2 bag: it has no {} table{} ({}; {})",
                  file.string(), fmt::join(missing, " or "), missing.size() > 1 ? "s" : "",
                  tables.empty() ? std::string("it has no tables at all")
                                 : fmt::format("its tables: {}", fmt::join(quoted, ", ")),
                  kRosbag2Tables));
}

/// The topics table by id.
Result<TopicsById> ReadTopics(sqlite3* db, const fs::path& file) {
  constexpr std::string_view kWhat = "reading its topics table";
  AVP_ASSIGN_OR_RETURN(
      Statement s,
      Prepare(db, "SELECT id, name, type, serialization_format FROM topics ORDER BY id", file,
              kWhat));
  TopicsById topics;
  int rc = SQLITE_ROW;
  while ((rc = sqlite3_step(s.get())) == SQLITE_ROW) {
    TopicRow row{ColumnText(s.get(), 1), ColumnText(s.get(), 2), ColumnText(s.get(), 3)};
    // rosbag2 always writes it; "cdr" is what every ROS 2 middleware serializes to.
    if (row.serialization_format.empty()) row.serialization_format = "cdr";
    topics[sqlite3_column_int64(s.get(), 0)] = std::move(row);
  }
  if (rc != SQLITE_DONE) return StepError(db, rc, file, kWhat);
  return topics;
}

/// Each topic's message count (topics without messages: 0) into `info`. Best effort: a damaged
/// messages table leaves the counts out (the bag cannot say), and the stream reports the damage
/// after delivering the intact messages.
void CountMessages(sqlite3* db, const fs::path& file, const TopicsById& topics, BagInfo& info) {
  Result<Statement> s = Prepare(db, "SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id",
                                file, "counting messages");
  if (!s.ok()) return;
  std::map<std::string, uint64_t> counts;
  for (const auto& [id, topic] : topics) counts.emplace(topic.name, 0);
  int rc = SQLITE_ROW;
  while ((rc = sqlite3_step(s->get())) == SQLITE_ROW) {
    auto it = topics.find(sqlite3_column_int64(s->get(), 0));
    // Messages of an unknown topic id are reported when the stream reaches them.
    if (it == topics.end()) continue;
    counts[it->second.name] += static_cast<uint64_t>(sqlite3_column_int64(s->get(), 1));
  }
  if (rc == SQLITE_DONE) info.topic_counts = std::move(counts);
}

/// `in` decompressed: one zstd frame that records its decompressed size (as rosbag2's zstd
/// compressor writes each message in compression_mode MESSAGE).
Result<std::vector<uint8_t>> DecompressZstd(std::span<const uint8_t> in, std::string_view where) {
  const unsigned long long size = ZSTD_getFrameContentSize(in.data(), in.size());
  if (size == ZSTD_CONTENTSIZE_ERROR) {
    return ParseError(
        fmt::format("{}: its {} bytes of data are not a zstd frame (the bag's messages were to be "
                    "zstd-compressed one by one: metadata.yaml's compression_mode MESSAGE)",
                    where, in.size()));
  }
  if (size == ZSTD_CONTENTSIZE_UNKNOWN) {
    return ParseError(fmt::format(
        "{}: its zstd frame does not record its decompressed size (rosbag2's compressor writes "
        "it), so avp cannot bound the memory it needs",
        where));
  }
  // The limit of MCAP's compressed chunks too: a message cannot claim more than a file may hold.
  AVP_RETURN_IF_ERROR(
      io::MaxFileBytes().Check(fmt::format("{}: its zstd frame's decompressed size", where), size));
  std::vector<uint8_t> out(static_cast<size_t>(size));
  const size_t got = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
  if (ZSTD_isError(got) != 0) {
    return ParseError(
        fmt::format("{}: its zstd data does not decompress: {}", where, ZSTD_getErrorName(got)));
  }
  if (got != out.size()) {
    return ParseError(fmt::format("{}: its zstd frame says {} bytes but decompresses to {}", where,
                                  out.size(), got));
  }
  return out;
}

/// `status` with `note` appended to its message (no-op when OK or the note is empty).
Status WithNote(const Status& status, const std::string& note) {
  if (status.ok() || note.empty()) return status;
  return Status(status.code(), status.message() + note);
}

class SqliteSource final : public MessageSource {
 public:
  /// `truncated`: a note for errors when the file is shorter than its header says, or "".
  SqliteSource(fs::path file, Database db, TopicsById topics, BagInfo info, bool zstd,
               std::string truncated)
      : file_(std::move(file)),
        db_(std::move(db)),
        topics_(std::move(topics)),
        info_(std::move(info)),
        zstd_(zstd),
        truncated_(std::move(truncated)) {}

  /// Prepares the two statements that stream the messages.
  Status Start() {
    AVP_ASSIGN_OR_RETURN(
        order_, Prepare(db_.get(), "SELECT id, timestamp FROM messages ORDER BY timestamp, id",
                        file_, "reading its messages"));
    AVP_ASSIGN_OR_RETURN(
        fetch_, Prepare(db_.get(), "SELECT topic_id, data FROM messages WHERE id = ?1", file_,
                        "reading its messages"));
    return Status::Ok();
  }

  const BagInfo& info() const override { return info_; }

  Result<std::optional<BagMessage>> Next() override {
    if (!error_.ok()) return error_;
    if (done_) return std::optional<BagMessage>();
    const int rc = sqlite3_step(order_.get());
    if (rc == SQLITE_DONE) {
      done_ = true;
      bytes_read_ = info_.file_bytes;
      Release();
      return std::optional<BagMessage>();
    }
    if (rc != SQLITE_ROW) return Fail(Damaged(rc));
    const int64_t id = sqlite3_column_int64(order_.get(), 0);
    if (sqlite3_column_type(order_.get(), 1) != SQLITE_INTEGER) {
      return Fail(RowError(id, fmt::format("its timestamp is {}, not an integer (ns since the "
                                           "epoch)",
                                           QuoteText(ColumnText(order_.get(), 1)))));
    }
    const int64_t timestamp = sqlite3_column_int64(order_.get(), 1);
    if (timestamp < 0) {
      return Fail(RowError(
          id, fmt::format("its timestamp {} is negative (rosbag2 writes ns since the epoch)",
                          timestamp)));
    }
    Result<BagMessage> message = Fetch(id, static_cast<uint64_t>(timestamp));
    if (!message.ok()) return Fail(message.status());
    last_id_ = id;
    ++delivered_;
    return std::optional<BagMessage>(std::move(message).value());
  }

  uint64_t bytes_read() const override { return std::min(bytes_read_, info_.file_bytes); }

 private:
  /// Message row `id`: its topic and data.
  Result<BagMessage> Fetch(int64_t id, uint64_t timestamp) {
    sqlite3_stmt* s = fetch_.get();
    sqlite3_reset(s);
    sqlite3_bind_int64(s, 1, id);
    const int rc = sqlite3_step(s);
    if (rc != SQLITE_ROW) return Damaged(rc, id);
    const int64_t topic_id = sqlite3_column_int64(s, 0);
    auto topic = topics_.find(topic_id);
    if (topic == topics_.end()) {
      return RowError(
          id, fmt::format("its topic_id {} is not in the topics table ({})", topic_id, TopicIds()));
    }
    if (sqlite3_column_type(s, 1) == SQLITE_NULL) {
      return RowError(
          id, fmt::format("its data is NULL (a message on {})", QuoteText(topic->second.name)));
    }
    // The blob stays valid until the statement is reset (a zero-length one may be null).
    const auto* bytes = static_cast<const uint8_t*>(sqlite3_column_blob(s, 1));
    const std::span<const uint8_t> stored(
        bytes, bytes != nullptr ? static_cast<size_t>(sqlite3_column_bytes(s, 1)) : 0);
    bytes_read_ += stored.size();
    BagMessage m{.topic = topic->second.name,
                 .type = topic->second.type,
                 .encoding = topic->second.serialization_format,
                 .log_time = timestamp,
                 .data = {}};
    if (!zstd_) {
      m.data.assign(stored.begin(), stored.end());
    } else {
      Result<std::vector<uint8_t>> data = DecompressZstd(stored, RowWhere(id));
      if (!data.ok()) {
        return Status(data.status().code(),
                      fmt::format("{}; {}", data.status().message(), Delivered()));
      }
      m.data = std::move(data).value();
    }
    sqlite3_reset(s);
    return m;
  }

  std::string RowWhere(int64_t id) const {
    return fmt::format("{}: message row {}", file_.string(), id);
  }

  /// How far the intact part goes, for errors.
  std::string Delivered() const {
    if (delivered_ == 0) return "no message before it was read";
    return fmt::format("the {} message{} before it (up to row {}) were read", delivered_,
                       delivered_ == 1 ? "" : "s", last_id_);
  }

  Status RowError(int64_t id, std::string what) const {
    return InvalidArgumentError(
        fmt::format("{}: {}: the bag is damaged; {}", RowWhere(id), what, Delivered()));
  }

  /// sqlite3_step failed: the database is damaged past the last good row.
  Status Damaged(int rc, std::optional<int64_t> id = std::nullopt) const {
    const std::string at =
        id ? fmt::format("at message row {}", *id)
           : fmt::format("after message row {} (message {} by time)", last_id_, delivered_);
    const std::string where = delivered_ == 0 && !id ? "at its first message" : at;
    // SQLITE_DONE: the timestamp index lists a row that the table no longer holds (the table's
    // page is lost).
    const bool damaged = rc == SQLITE_CORRUPT || rc == SQLITE_NOTADB || rc == SQLITE_DONE;
    const std::string what =
        rc == SQLITE_DONE ? std::string("the timestamp index lists the row, the table lacks it")
                          : SqliteMessage(db_.get(), rc);
    return ParseError(fmt::format("{}: SQLite stops reading {}: {}{}; {}", file_.string(), where,
                                  what,
                                  !truncated_.empty() ? truncated_
                                  : damaged           ? " (the file is damaged or truncated)"
                                                      : "",
                                  Delivered()));
  }

  std::string TopicIds() const {
    std::vector<std::string> ids;
    for (const auto& [id, topic] : topics_) {
      if (ids.size() == kMaxListed) {
        ids.push_back(fmt::format("{} more", topics_.size() - kMaxListed));
        break;
      }
      ids.push_back(std::to_string(id));
    }
    if (ids.empty()) return "it is empty";
    return fmt::format("its ids: {}", fmt::join(ids, ", "));
  }

  Status Fail(Status error) {
    error_ = std::move(error);
    Release();
    return error_;
  }

  /// Closes the database once the stream is over (statements first).
  void Release() {
    fetch_.reset();
    order_.reset();
    db_.reset();
  }

  fs::path file_;
  Database db_;  // before the statements: destroyed after them
  Statement order_;
  Statement fetch_;
  TopicsById topics_;
  BagInfo info_;
  bool zstd_ = false;
  std::string truncated_;
  Status error_;
  bool done_ = false;
  int64_t last_id_ = 0;
  uint64_t delivered_ = 0;
  uint64_t bytes_read_ = 0;
};

}  // namespace

Result<std::unique_ptr<MessageSource>> OpenSqliteSource(const fs::path& file) {
  return OpenSqliteSource(file, "");
}

Result<std::unique_ptr<MessageSource>> OpenSqliteSource(const fs::path& file,
                                                        std::string_view message_compression) {
  if (!message_compression.empty() && message_compression != "zstd") {
    return InvalidArgumentError(fmt::format(
        "{}: message compression {} is not one avp reads (\"\" or zstd, rosbag2's compressor)",
        file.string(), QuoteText(message_compression)));
  }
  AVP_ASSIGN_OR_RETURN(
      const uint64_t file_bytes,
      io::CheckReadableFile(file, "rosbag2 SQLite 3 file", std::numeric_limits<uint64_t>::max()));
  AVP_ASSIGN_OR_RETURN(const std::string header, ReadSqliteHeader(file));
  AVP_ASSIGN_OR_RETURN(Database db, OpenDatabase(file));
  std::string truncated;
  if (const uint64_t want = HeaderDatabaseBytes(header); want > file_bytes) {
    // SQLite refuses a file shorter than its header says before reading anything; with the
    // recovery tools' setting it reads the pages that are there (the connection is read-only),
    // so the messages before the cut are delivered.
    sqlite3_db_config(db.get(), SQLITE_DBCONFIG_WRITABLE_SCHEMA, 1, nullptr);
    truncated = fmt::format(" (the file is truncated: {} of the {} bytes its header gives)",
                            file_bytes, want);
  }
  AVP_RETURN_IF_ERROR(WithNote(CheckRosbag2Tables(db.get(), file), truncated));
  Result<TopicsById> read_topics = ReadTopics(db.get(), file);
  if (!read_topics.ok()) return WithNote(read_topics.status(), truncated);
  TopicsById topics = std::move(read_topics).value();

  BagInfo info;
  info.format = message_compression.empty() ? "rosbag2 SQLite 3"
                                            : "rosbag2 SQLite 3 (zstd-compressed messages)";
  info.files = {file};
  info.file_bytes = file_bytes;
  for (const auto& [id, topic] : topics) info.topic_types.emplace(topic.name, topic.type);
  CountMessages(db.get(), file, topics, info);

  auto source =
      std::make_unique<SqliteSource>(file, std::move(db), std::move(topics), std::move(info),
                                     !message_compression.empty(), std::move(truncated));
  AVP_RETURN_IF_ERROR(source->Start());
  return std::unique_ptr<MessageSource>(std::move(source));
}

}  // namespace avp::ros::bag
