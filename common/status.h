// Status and StatusOr<T>: the error channel for failures caused by the world
// (I/O, bad files, bad network bytes). Broken internal invariants use
// HOLO_CHECK instead, which aborts with a message.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace holo {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,    // a caller or a config gave a bad value
  kNotFound,           // a file, key or item does not exist
  kDataLoss,           // bytes are malformed or truncated
  kUnavailable,        // a peer or device is not reachable now
  kUnsupportedVersion, // a format or protocol version we do not speak
  kOutOfRange,         // an index or seek target is past the end
  kInternal,           // a library call failed unexpectedly
};

const char* StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }
  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "kInvalidArgument: fx must be > 0, got -1" or "OK".
  std::string ToString() const;

  // Returns a copy with `context` prepended: "rig.yaml: <message>".
  Status WithContext(const std::string& context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

// A number as error messages show it, in the stream's default format ("640",
// "0.25", "1e+30", "nan"): "fx must be > 0, got -1".
std::string FormatNumber(double v);

inline Status OkStatus() { return Status(); }
inline Status InvalidArgument(std::string m) { return {StatusCode::kInvalidArgument, std::move(m)}; }
inline Status NotFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status DataLoss(std::string m) { return {StatusCode::kDataLoss, std::move(m)}; }
inline Status Unavailable(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
inline Status UnsupportedVersion(std::string m) { return {StatusCode::kUnsupportedVersion, std::move(m)}; }
inline Status OutOfRange(std::string m) { return {StatusCode::kOutOfRange, std::move(m)}; }
inline Status Internal(std::string m) { return {StatusCode::kInternal, std::move(m)}; }

[[noreturn]] void CheckFailed(const char* file, int line, const char* expr, const std::string& msg);

#define HOLO_CHECK(expr)                                                \
  do {                                                                  \
    if (!(expr)) ::holo::CheckFailed(__FILE__, __LINE__, #expr, "");    \
  } while (0)
#define HOLO_CHECK_MSG(expr, msg)                                       \
  do {                                                                  \
    if (!(expr)) ::holo::CheckFailed(__FILE__, __LINE__, #expr, (msg)); \
  } while (0)

template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(const T& value) : value_(value) {}                 // NOLINT: implicit by design
  StatusOr(T&& value) : value_(std::move(value)) {}            // NOLINT
  StatusOr(Status status) : status_(std::move(status)) {      // NOLINT
    HOLO_CHECK_MSG(!status_.ok(), "StatusOr built from an OK status without a value");
  }

  bool ok() const { return status_.ok(); }
  const Status& status() const { return status_; }

  const T& value() const& { CheckOk(); return *value_; }
  T& value() & { CheckOk(); return *value_; }
  T&& value() && { CheckOk(); return std::move(*value_); }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

 private:
  void CheckOk() const {
    if (!status_.ok()) CheckFailed(__FILE__, __LINE__, "StatusOr::value()", status_.ToString());
  }
  Status status_;
  std::optional<T> value_;
};

#define HOLO_CONCAT_INNER(a, b) a##b
#define HOLO_CONCAT(a, b) HOLO_CONCAT_INNER(a, b)

// Returns from the current function if `expr` (a Status) is not OK.
#define HOLO_RETURN_IF_ERROR(expr)              \
  do {                                          \
    ::holo::Status holo_status_ = (expr);       \
    if (!holo_status_.ok()) return holo_status_; \
  } while (0)

// HOLO_ASSIGN_OR_RETURN(auto x, MaybeX()); declares x or returns the error.
#define HOLO_ASSIGN_OR_RETURN(lhs, expr) \
  HOLO_ASSIGN_OR_RETURN_IMPL(HOLO_CONCAT(holo_statusor_, __LINE__), lhs, expr)
#define HOLO_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                               \
  if (!tmp.ok()) return tmp.status();              \
  lhs = std::move(tmp).value()

}  // namespace holo
