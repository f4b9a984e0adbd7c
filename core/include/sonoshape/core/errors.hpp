#pragma once
// Typed exceptions for broken preconditions of the algorithms (design.md: I/O uses Status).
#include <stdexcept>
#include <string>

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

}  // namespace sonoshape
