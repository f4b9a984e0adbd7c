// Hostile files and full disks as the user meets them (issue 40, C4 and "Silent wrong output"):
// the `sonoshape` command on devices, FIFOs, folders and crafted files, run with a time limit so
// that a hang fails the test instead of stalling it. Each must end in the right result or a clear
// error naming the file and the field.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace hostile_files_test {
namespace {

namespace fs = std::filesystem;
using sonoshape::testing::contains;
using sonoshape::testing::file_text;
using sonoshape::testing::TempDir;

struct Outcome {
  int exit_code = -1;  // -1: killed (the time limit) or ended by a signal
  std::string output;
};

class HostileFiles : public ::testing::Test {
 protected:
  std::string path(const std::string& name) const { return (dir_.path() / name).string(); }
  // `sonoshape arguments`, killed after `limit_s` (a reader blocked on a FIFO or reading
  // /dev/zero to its end never returns).
  Outcome run(const std::string& arguments, double limit_s = 20.0) const {
    const fs::path log = dir_.path() / "log.txt";
    const pid_t pid =
        sonoshape::testing::spawn(std::string(SONOSHAPE_BINARY) + " " + arguments, log);
    Outcome out;
    out.exit_code = sonoshape::testing::wait_exit(pid, limit_s);
    out.output = file_text(log);
    return out;
  }
  static void expect_error(const Outcome& out, const std::string& words) {
    EXPECT_TRUE(out.exit_code == 1 || out.exit_code == 2) << out.exit_code << ": " << out.output;
    EXPECT_TRUE(contains(out.output, "error:"));
    EXPECT_TRUE(contains(out.output, words));
  }
  std::string fifo(const std::string& name) const {
    EXPECT_EQ(::mkfifo(path(name).c_str(), 0600), 0);
    return path(name);
  }

  TempDir dir_;
};

// Issue 40, C4: /dev/zero, /dev/urandom and FIFOs as meshes, slice sets, configs, sequences or
// keys ran out of memory or hung; a folder failed with "basic_filebuf::underflow".
TEST_F(HostileFiles, DevicesFifosAndFoldersAreRefusedAsInputsNamingThem) {
  const std::string out = " -o " + path("out");
  const std::string device = ": it is a character device, not a regular file";
  const std::string pipe = ": it is a FIFO (named pipe), not a regular file";
  expect_error(run("reconstruct /dev/zero" + out), "slice set /dev/zero" + device);
  const std::string slices = fifo("set.slices.json");
  expect_error(run("reconstruct " + slices + out), "slice set " + slices + pipe);
  fs::create_directories(path("folder.slices.json"));
  expect_error(run("reconstruct " + path("folder.slices.json") + out),
               "slice set " + path("folder.slices.json") + ": it is a folder");
  expect_error(run("slice --mesh 1:/dev/urandom --count 2" + out + ".slices.json"),
               "mesh file /dev/urandom" + device);
  const std::string mesh = fifo("organ.stl");
  expect_error(run("slice --mesh 1:" + mesh + " --count 2" + out + ".slices.json"),
               "mesh file " + mesh + pipe);
  expect_error(run("segment /dev/zero" + out + ".slices.json"), "sequence file /dev/zero" + device);
  const std::string sweep = fifo("sweep.igs.mha");
  expect_error(run("segment " + sweep + out + ".slices.json"), "sequence file " + sweep + pipe);
  const std::string key = fifo("server.pub");
  expect_error(run("listen tcp://127.0.0.1:1 --server-key " + key + out),
               "the CURVE public key " + key + pipe);
  const std::string journal_dir = path("scan");
  fs::create_directories(journal_dir);
  ASSERT_EQ(::mkfifo((fs::path(journal_dir) / "scan.journal").c_str(), 0600), 0);
  expect_error(run("scan --resume " + journal_dir),
               "the journal " + journal_dir + "/scan.journal" + pipe);
}

// A binary STL of `triangles` (three vertices each, in mm).
void write_stl(const fs::path& path,
               const std::vector<std::array<std::array<float, 3>, 3>>& triangles) {
  std::ofstream out(path, std::ios::binary);
  out << std::string(80, ' ');
  const auto count = static_cast<std::uint32_t>(triangles.size());
  out.write(reinterpret_cast<const char*>(&count), 4);
  for (const auto& triangle : triangles) {
    const float normal[3] = {0, 0, 0};
    out.write(reinterpret_cast<const char*>(normal), 12);
    for (const auto& vertex : triangle) out.write(reinterpret_cast<const char*>(vertex.data()), 12);
    out.write("\0\0", 2);
  }
}

// The 12 triangles of the cube [0, size]^3, outward.
std::vector<std::array<std::array<float, 3>, 3>> cube(float size) {
  const float s = size;
  const std::array<std::array<float, 3>, 8> v = {
      {{0, 0, 0}, {s, 0, 0}, {s, s, 0}, {0, s, 0}, {0, 0, s}, {s, 0, s}, {s, s, s}, {0, s, s}}};
  const int faces[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                            {2, 3, 7}, {2, 7, 6}, {1, 2, 6}, {1, 6, 5}, {0, 4, 7}, {0, 7, 3}};
  std::vector<std::array<std::array<float, 3>, 3>> out;
  for (const auto& f : faces) out.push_back({v[f[0]], v[f[1]], v[f[2]]});
  return out;
}

// Issue 40: an STL with a vertex at 3e38 (the box then holds the cube nowhere) or with only
// zero-area triangles gave a set of empty slices and exit 0.
TEST_F(HostileFiles, AMeshThatNoPlaneCutsIsAnErrorNotASetOfEmptySlices) {
  auto far = cube(10.0f);
  far.push_back({{{0, 0, 0}, {3e38f, 0, 0}, {3e38f, 0, 0}}});
  write_stl(path("far.stl"), far);
  const Outcome far_out =
      run("slice --mesh 1:" + path("far.stl") + " --count 20 -o " + path("far.slices.json"));
  expect_error(far_out, "none of the 20 planes cuts a region out of 1:" + path("far.stl"));
  EXPECT_FALSE(fs::exists(path("far.slices.json")));

  // Twelve triangles of three distinct points on one line: no area, nothing enclosed.
  std::vector<std::array<std::array<float, 3>, 3>> flat;
  for (float k = 0; k < 12; ++k)
    flat.push_back(
        {{{k, 2 * k, 3 * k}, {k + 1, 2 * k + 2, 3 * k + 3}, {k + 2, 2 * k + 4, 3 * k + 6}}});
  write_stl(path("flat.stl"), flat);
  expect_error(
      run("slice --mesh 1:" + path("flat.stl") + " --count 20 -o " + path("flat.slices.json")),
      "planes cuts a region out of");
  // The cube itself slices.
  write_stl(path("cube.stl"), cube(10.0f));
  const Outcome good =
      run("slice --mesh 1:" + path("cube.stl") + " --count 5 -o " + path("cube.slices.json"));
  EXPECT_EQ(good.exit_code, 0) << good.output;
}

// Issue 40: `reconstruct --stats /dev/full` exited 0 without the file (the stream's buffer was
// flushed, and failed, only when it closed).
TEST_F(HostileFiles, StatsThatCannotBeWrittenFailTheRun) {
  const std::string set =
      std::string(SONOSHAPE_SOURCE_DIR) + "/data/examples/two_labels.slices.json";
  const Outcome out = run("reconstruct " + set + " -o " + path("recon") + " --stats /dev/full");
  EXPECT_NE(out.exit_code, 0) << out.output;
  EXPECT_TRUE(contains(out.output, "cannot write stats to /dev/full: No space left on device"));
}

// Issue 40: `keys -o ''` wrote the hidden files .key and .pub.
TEST_F(HostileFiles, KeysWithoutANameWriteNothing) {
  for (const std::string& name : {std::string("''"), path("keys") + "/"}) {
    const Outcome out = run("keys -o " + name);
    expect_error(out, "names no file: give NAME");
  }
  EXPECT_FALSE(fs::exists(".key"));
  EXPECT_FALSE(fs::exists(path("keys") + "/.key"));
}

// Issue 40, C5: 100 copies of one slice took 28 s (20 distinct slices: 0.4 s): each copy was
// compared point by point with every other. Copies are merged at input, each compared once with
// the first: the set reconstructs to the very meshes of the set without the copies.
TEST_F(HostileFiles, AHundredCopiesOfASliceReconstructAsOne) {
  const std::string mesh = std::string(SONOSHAPE_SOURCE_DIR) + "/data/models/spot.obj";
  ASSERT_EQ(run("slice --mesh 1:" + mesh + " --count 4 -o " + path("one.slices.json")).exit_code,
            0);
  nlohmann::json set = nlohmann::json::parse(file_text(path("one.slices.json")));
  const nlohmann::json copied = set["slices"][1];
  for (int k = 0; k < 99; ++k) set["slices"].push_back(copied);
  std::ofstream(path("hundred.slices.json")) << set.dump();
  const auto started = std::chrono::steady_clock::now();
  const Outcome hundred = run("reconstruct " + path("hundred.slices.json") + " -o " + path("b"));
  const double hundred_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  ASSERT_EQ(hundred.exit_code, 0) << hundred.output;
  EXPECT_TRUE(contains(hundred.output, "identical contents; merged"));
  const Outcome one = run("reconstruct " + path("one.slices.json") + " -o " + path("a"));
  ASSERT_EQ(one.exit_code, 0) << one.output;
  const std::string a = file_text(dir_.path() / "a" / "label_1.ply");
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, file_text(dir_.path() / "b" / "label_1.ply"));
  std::printf("100 copies of one slice among 4: reconstruct took %.2f s\n", hundred_s);
}

}  // namespace
}  // namespace hostile_files_test
