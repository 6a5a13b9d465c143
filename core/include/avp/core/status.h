#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace avp {

/// Outcome categories. Expected failures (an unreachable pose, a missing file, a malformed config)
/// are reported through `Status` / `Result<T>`, never through a crash.
enum class StatusCode {
  kOk = 0,
  kInvalidArgument,     ///< a value is outside its documented domain
  kNotFound,            ///< a named thing (scenario, file, link) does not exist
  kParseError,          ///< a file or string could not be parsed
  kIoError,             ///< reading or writing failed
  kUnreachable,         ///< no joint configuration reaches the requested pose
  kFailedPrecondition,  ///< the call is not valid in the current state
  kOutOfRange,          ///< an index or coordinate lies outside the valid range
  kInternal,            ///< a bug: an invariant did not hold
  kDeadlineExceeded,    ///< a bounded wait ran out (a camera that stops, an arm that never arrives)
  kUnavailable,         ///< a peer (robot, camera, service) is not there or stopped answering
  kCancelled,           ///< the caller asked to stop (Ctrl-C)
  kResourceExhausted,   ///< input asked for more than a named limit allows (core/limits.h)
};

std::string_view ToString(StatusCode code);

/// A small status in the LevelDB style: OK, or a code plus a message naming the bad value.
class [[nodiscard]] Status {
 public:
  Status() = default;  // OK
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return {}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }

  /// "InvalidArgument: width (-13) must be > 0", or "OK".
  std::string ToString() const;

  /// Returns a copy with `context + ": "` prepended to the message (no-op when OK).
  Status WithContext(std::string_view context) const;

  friend bool operator==(const Status& a, const Status& b) {
    return a.code_ == b.code_ && a.message_ == b.message_;
  }

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

Status InvalidArgumentError(std::string message);
Status NotFoundError(std::string message);
Status ParseError(std::string message);
Status IoError(std::string message);
Status UnreachableError(std::string message);
Status FailedPreconditionError(std::string message);
Status OutOfRangeError(std::string message);
Status InternalError(std::string message);
Status DeadlineExceededError(std::string message);
Status UnavailableError(std::string message);
Status CancelledError(std::string message);
Status ResourceExhaustedError(std::string message);

/// A value or an error status (C++20 has no std::expected).
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : data_(std::move(value)) {}        // NOLINT(google-explicit-constructor)
  Result(Status status) : data_(std::move(status)) {  // NOLINT(google-explicit-constructor)
    assert(!std::get<Status>(data_).ok() && "Result<T> built from an OK status without a value");
  }

  bool ok() const { return std::holds_alternative<T>(data_); }
  explicit operator bool() const { return ok(); }

  /// The error, or OK when a value is held.
  Status status() const { return ok() ? Status::Ok() : std::get<Status>(data_); }

  /// The value; throws avp::Error carrying the status message when there is none.
  const T& value() const& {
    ThrowIfError();
    return std::get<T>(data_);
  }
  T& value() & {
    ThrowIfError();
    return std::get<T>(data_);
  }
  T&& value() && {
    ThrowIfError();
    return std::get<T>(std::move(data_));
  }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

  T value_or(T fallback) const& { return ok() ? std::get<T>(data_) : std::move(fallback); }

 private:
  void ThrowIfError() const;
  std::variant<T, Status> data_;
};

[[noreturn]] void ThrowStatus(const Status& status);

template <typename T>
void Result<T>::ThrowIfError() const {
  if (!ok()) ThrowStatus(std::get<Status>(data_));
}

}  // namespace avp

/// Returns early from a function returning Status or Result<T> when `expr` (a Status) is not OK.
#define AVP_RETURN_IF_ERROR(expr)                      \
  do {                                                 \
    ::avp::Status avp_status_tmp_ = (expr);            \
    if (!avp_status_tmp_.ok()) return avp_status_tmp_; \
  } while (false)

#define AVP_STATUS_CONCAT_INNER_(a, b) a##b
#define AVP_STATUS_CONCAT_(a, b) AVP_STATUS_CONCAT_INNER_(a, b)

/// `AVP_ASSIGN_OR_RETURN(auto x, MaybeX());` assigns the value or returns the error status.
#define AVP_ASSIGN_OR_RETURN(lhs, expr) \
  AVP_ASSIGN_OR_RETURN_IMPL_(AVP_STATUS_CONCAT_(avp_result_, __LINE__), lhs, expr)
#define AVP_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                               \
  if (!tmp.ok()) return tmp.status();              \
  lhs = std::move(tmp).value()
