// check_input_file / read_input_file: only regular files are read; devices, FIFOs and folders
// are refused at once, naming the file and what it is (issue 40, C4).
#include "sonoshape/core/input_file.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>

#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::input_file_test {
namespace {

using testing::contains;
using testing::TempDir;

TEST(InputFile, ReadsARegularFileWholeAndAProcFileToItsEnd) {
  const TempDir dir;
  std::ofstream(dir.path() / "a.txt") << std::string(200000, 'x');
  const Result<std::string> bytes = read_input_file(dir.path() / "a.txt", "slice set");
  ASSERT_TRUE(bytes) << bytes.message();
  EXPECT_EQ(bytes->size(), 200000u);
  EXPECT_TRUE(check_input_file(dir.path() / "a.txt", "slice set"));
  // /proc files say size 0 and are regular: read to their end.
  const Result<std::string> status = read_input_file("/proc/self/status", "status");
  ASSERT_TRUE(status) << status.message();
  EXPECT_TRUE(contains(*status, "VmRSS"));
}

TEST(InputFile, RefusesDevicesAFifoAndAFolderNamingThemWithoutBlocking) {
  const TempDir dir;
  const std::filesystem::path fifo = dir.path() / "pipe.stl";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const struct {
    std::filesystem::path path;
    const char* kind;
  } cases[] = {{"/dev/zero", "a character device"},
               {"/dev/urandom", "a character device"},
               {fifo, "a FIFO (named pipe)"},
               {dir.path(), "a folder"}};
  for (const auto& c : cases) {
    const Result<std::string> read = read_input_file(c.path, "mesh file");
    ASSERT_FALSE(read) << c.path;
    EXPECT_TRUE(contains(read.message(), "cannot read mesh file " + c.path.string() + ": it is " +
                                             c.kind + ", not a regular file"));
    const Status checked = check_input_file(c.path, "mesh file");
    ASSERT_FALSE(checked) << c.path;
    EXPECT_EQ(checked.message(), read.message());
  }
}

TEST(InputFile, AMissingFileIsNamedWithTheFix) {
  const Result<std::string> read = read_input_file("/nonexistent/x.json", "config");
  ASSERT_FALSE(read);
  EXPECT_TRUE(contains(read.message(),
                       "cannot read config /nonexistent/x.json: no such file; check the path"));
}

}  // namespace
}  // namespace sonoshape::input_file_test
