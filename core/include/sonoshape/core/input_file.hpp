#pragma once
// Opening a file of input (a mesh, a slice set, a config, a sequence, a key, a journal) the one
// way every reader does: only a regular file is read. A folder fails deep inside the standard
// library ("basic_filebuf::underflow"), /dev/zero or /dev/urandom never end (the reader runs out
// of memory), and a FIFO blocks the open until some other program writes (issue 40, C4).
#include <filesystem>
#include <string>
#include <string_view>

#include "sonoshape/core/status.hpp"

namespace sonoshape {

/// Ok when `path` names a regular file (after symbolic links) that exists; otherwise an error
/// naming it, its `what` ("mesh file", "slice set", ...), what it is instead and the fix, e.g.
/// "cannot read mesh file /dev/zero: it is a character device, not a regular file; give the path
/// of a file". For readers that hand the path on to a library (pugixml, OpenCV).
Status check_input_file(const std::filesystem::path& path, std::string_view what);

/// The bytes of the regular file `path`, read whole. Refuses what check_input_file refuses
/// without blocking (a FIFO is opened non-blocking and refused), and names the file, its `what`
/// and the system's reason when it cannot be opened or read.
Result<std::string> read_input_file(const std::filesystem::path& path, std::string_view what);

}  // namespace sonoshape
