#pragma once
// Status / Result<T> for I/O, devices and network: failures a user can act on.
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>

namespace sonoshape {

/// Success, or a message that says what went wrong, where, and how to fix it.
class Status {
 public:
  Status() = default;
  static Status ok() { return Status(); }
  static Status error(std::string message) { return Status(std::move(message)); }

  bool is_ok() const { return !message_.has_value(); }
  explicit operator bool() const { return is_ok(); }
  const std::string& message() const {
    static const std::string kEmpty;
    return message_ ? *message_ : kEmpty;
  }

 private:
  explicit Status(std::string message) : message_(std::move(message)) {}
  std::optional<std::string> message_;
};

/// A value or the Status that explains why there is none.
template <typename T>
class Result {
 public:
  Result(T value) : data_(std::move(value)) {}        // NOLINT: implicit by design
  Result(Status status) : data_(std::move(status)) {  // NOLINT
    if (std::get<Status>(data_).is_ok()) throw std::logic_error("Result built from an ok Status");
  }

  bool is_ok() const { return std::holds_alternative<T>(data_); }
  explicit operator bool() const { return is_ok(); }
  const T& value() const& { return checked(); }
  T& value() & { return checked(); }
  T&& value() && { return std::move(checked()); }
  const T& operator*() const& { return checked(); }
  T& operator*() & { return checked(); }
  const T* operator->() const { return &checked(); }
  T* operator->() { return &checked(); }
  Status status() const { return is_ok() ? Status::ok() : std::get<Status>(data_); }
  const std::string& message() const { return std::get<Status>(data_).message(); }

 private:
  T& checked() {
    if (!is_ok()) throw std::logic_error("Result has no value: " + message());
    return std::get<T>(data_);
  }
  const T& checked() const {
    if (!is_ok()) throw std::logic_error("Result has no value: " + message());
    return std::get<T>(data_);
  }
  std::variant<T, Status> data_;
};

}  // namespace sonoshape
