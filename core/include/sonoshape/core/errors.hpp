#pragma once
// Typed exceptions: broken preconditions of the algorithms, and input that breaks its format
// (design.md: a reader throws InputError while parsing and returns a Status at its entry point).
#include <stdexcept>
#include <string>
#include <utility>

namespace sonoshape {

/// Base of every exception sonoshape throws on purpose.
struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Geometric input the algorithms cannot work with (degenerate plane, empty box, ...).
struct GeometryError : Error {
  using Error::Error;
};

/// Input that is valid for the file format but not (yet) supported by the engine.
struct UnsupportedInput : Error {
  using Error::Error;
};

/// Input that breaks its format: a file, a header field, a peer's message. It names the file
/// (when the thrower knows it), the element ("line 12", "vertex 3", "labels[2].grey_mean") and
/// the problem with its fix; what() joins the parts that are known with ": ". Every reader
/// throws this one type inside and turns it into its Status at its entry point (message_in).
class InputError : public Error {
 public:
  /// An error whose file the caller adds (message_in); `element` may be empty.
  InputError(std::string element, std::string problem)
      : InputError(std::string(), std::move(element), std::move(problem)) {}
  InputError(std::string file, std::string element, std::string problem)
      : Error(join(file, element, problem)),
        file_(std::move(file)),
        element_(std::move(element)),
        problem_(std::move(problem)) {}

  const std::string& file() const noexcept { return file_; }
  const std::string& element() const noexcept { return element_; }
  const std::string& problem() const noexcept { return problem_; }

  /// The whole message, "<file>: " in front unless the error names its own file.
  std::string message_in(const std::string& file) const {
    return file_.empty() ? file + ": " + what() : std::string(what());
  }

 private:
  static std::string join(const std::string& file, const std::string& element,
                          const std::string& problem) {
    std::string text;
    for (const std::string* part : {&file, &element, &problem})
      if (!part->empty()) text += (text.empty() ? "" : ": ") + *part;
    return text;
  }

  std::string file_;
  std::string element_;
  std::string problem_;
};

}  // namespace sonoshape
