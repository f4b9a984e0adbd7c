// Hostile input (issue 27, "What was measured"): each finding of the abuse run at ed734b2 as the
// user met it, the `sonoshape` command on a file from tests/data/hostile/ (or a simulated sweep
// patched here), run with a time and address-space limit so that a hang or a blow-up fails the
// test instead of stalling it. Each must end in the right result or a clear error that names the
// file, the element and the fix.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>

#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/sanitizer_slowdown.hpp"

namespace hostile_input_test {
namespace {

namespace fs = std::filesystem;
using sonoshape::testing::file_text;

const fs::path kCorpus = fs::path(SONOSHAPE_SOURCE_DIR) / "tests" / "data" / "hostile";

struct Outcome {
  int exit_code = -1;  // -1: killed (time limit or a signal)
  std::string output;
  double seconds = 0.0;
};

// Runs `sonoshape arguments` with at most `limit_s` seconds and 2 GiB of address space: a
// reader that spins or allocates for a lying count is killed and the test fails on it.
Outcome run_limited(const std::string& arguments, const fs::path& log, double limit_s = 30.0) {
  const auto start = std::chrono::steady_clock::now();
  const std::string line =
      "exec " + std::string(SONOSHAPE_BINARY) + " " + arguments + " > " + log.string() + " 2>&1";
  const pid_t pid = fork();
  if (pid == 0) {
    if (sonoshape::testing::kSanitizerBuild) {
      // The sanitizer's shadow memory needs terabytes of address space: the same 2 GiB bound
      // goes through its allocator (an allocation beyond it fails as std::bad_alloc would).
      for (const char* name : {"ASAN_OPTIONS", "TSAN_OPTIONS"}) {
        const char* given = std::getenv(name);
        const std::string options = std::string(given ? given : "") +
                                    ":allocator_may_return_null=1:max_allocation_size_mb=2048"
                                    ":hard_rss_limit_mb=2048";
        setenv(name, options.c_str(), 1);
      }
    } else {
      const rlim_t bytes = rlim_t{2} << 30;
      const rlimit limit{bytes, bytes};
      setrlimit(RLIMIT_AS, &limit);
    }
    execl("/bin/sh", "sh", "-c", line.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  Outcome out;
  out.exit_code =
      sonoshape::testing::wait_exit(pid, limit_s * sonoshape::testing::kSanitizerSlowdown);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  out.output = file_text(log);
  return out;
}

class HostileInput : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sonoshape_hostile_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
            std::to_string(::getpid()));  // two checkouts may run the suite at once
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string corpus(const std::string& name) { return (kCorpus / name).string(); }
  Outcome run(const std::string& arguments, double limit_s = 30.0) const {
    return run_limited(arguments, dir_ / "log.txt", limit_s);
  }
  // An error: exit code 1 or 2, "error:" and every one of `words` in the message.
  static void expect_error(const Outcome& out, std::initializer_list<std::string> words) {
    EXPECT_TRUE(out.exit_code == 1 || out.exit_code == 2) << out.exit_code << ": " << out.output;
    EXPECT_NE(out.output.find("error:"), std::string::npos) << out.output;
    EXPECT_EQ(out.output.find("bad_alloc"), std::string::npos) << out.output;
    for (const std::string& w : words)
      EXPECT_NE(out.output.find(w), std::string::npos) << "missing '" << w << "' in\n"
                                                       << out.output;
  }

  // A small simulated sweep (8 frames of 64x64) and its calibration, to patch.
  void simulate_sweep() const {
    const Outcome out =
        run("simulate --width-px 64 --height-px 64 --frames 8 --drop 0 "
            "--invalid 0 -o " +
            path("sw.igs.mha"));
    ASSERT_EQ(out.exit_code, 0) << out.output;
  }
  // Writes a copy of the simulated sweep with `from` replaced by `to` in its header.
  std::string patched_sweep(const std::string& name, const std::string& from,
                            const std::string& to) const {
    std::ifstream in(path("sw.igs.mha"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t header_end = bytes.find("ElementDataFile");
    std::string header = bytes.substr(0, header_end);
    EXPECT_TRUE(std::regex_search(header, std::regex(from))) << from;
    header = std::regex_replace(header, std::regex(from), to);
    std::ofstream(path(name), std::ios::binary) << header << bytes.substr(header_end);
    return path(name);
  }

  fs::path dir_;
};

// --- Lying counts: checked against the bytes present, no spin, no allocation first. ---

TEST_F(HostileInput, PlyElementWithoutPropertiesAndCount2e63IsSkippedNotLoopedOver) {
  const Outcome out = run("evaluate --recon " + corpus("edge_count_2e63.ply") +
                              " --truth 1:" + corpus("edge_count_2e63.ply"),
                          20.0);
  ASSERT_NE(out.exit_code, -1) << "killed after " << out.seconds << " s: " << out.output;
  EXPECT_EQ(out.exit_code, 0) << out.output;  // the triangle is read; the edges hold nothing
  EXPECT_LT(out.seconds, 10.0 * sonoshape::testing::kSanitizerSlowdown);
}

TEST_F(HostileInput, OffVertexCount1e9EndsEarlyNamingFileAndVertex) {
  const Outcome out = run("evaluate --recon " + corpus("vertex_count_1e9.off") +
                          " --truth 1:" + corpus("vertex_count_1e9.off"));
  expect_error(out, {"vertex_count_1e9.off", "vertex 4", "file ends early"});
}

TEST_F(HostileInput, MhaDimSizeAMillionFramesOverFourBytesIsRefusedBeforeAllocating) {
  const Outcome out = run("segment " + corpus("dimsize_512x512x1e6.mha") + " -o " + path("s.json"));
  expect_error(out,
               {"dimsize_512x512x1e6.mha", "DimSize needs 512x512x1000000", "DimSize is wrong"});
}

TEST_F(HostileInput, NrrdSizesAreCheckedAgainstTheDataBeforeAllocating) {
  // 2.6e11 samples: refused by the sample limit (already at ed734b2).
  Outcome out = run("segment " + corpus("sizes_512x512x1e6.igs.nrrd") + " -o " + path("s.json"));
  expect_error(out, {"sizes_512x512x1e6.igs.nrrd", "more than 2^36 samples"});
  // 262 MB over 4 gzip bytes: refused before allocating them (ed734b2 allocated, then called
  // the data corrupt).
  out = run("segment " + corpus("sizes_512x512x1000_over_4_gzip_bytes.igs.nrrd") + " -o " +
            path("s.json"));
  expect_error(out, {"sizes_512x512x1000_over_4_gzip_bytes.igs.nrrd", "262144000 bytes",
                     "only 4 gzip bytes", "'sizes' is wrong"});
}

TEST_F(HostileInput, CslVertexCount1e9EndsEarlyNamingLineAndCounts) {
  const Outcome out = run("reconstruct " + corpus("vertex_count_1e9.csl") + " -o " + path("o.ply"));
  expect_error(out, {"vertex_count_1e9.csl", "line", "ends early", "check the counts"});
}

TEST_F(HostileInput, CslDeclaring1e9LabelsWithOneUsedReconstructsThatOneQuickly) {
  const Outcome out =
      run("reconstruct " + corpus("nlabels_1e9.csl") + " -o " + path("o.ply"), 20.0);
  ASSERT_EQ(out.exit_code, 0) << "after " << out.seconds << " s: " << out.output;
  EXPECT_NE(out.output.find("materials 2..999999999 never occur"), std::string::npos) << out.output;
  EXPECT_LT(out.seconds, 10.0 * sonoshape::testing::kSanitizerSlowdown);
}

TEST_F(HostileInput, SliceSetDeclaring1000LabelsWithOneUsedCostsOneField) {
  // At ed734b2: 108 s and 5.3 GB (a field per declared label).
  const Outcome out =
      run("reconstruct " + corpus("labels_1000_one_used.slices.json") + " -o " + path("out"), 30.0);
  ASSERT_EQ(out.exit_code, 0) << "after " << out.seconds << " s: " << out.output;
  EXPECT_LT(out.seconds, 15.0 * sonoshape::testing::kSanitizerSlowdown);
  ASSERT_TRUE(fs::exists(path("out/label_1.ply")));
  EXPECT_GT(fs::file_size(path("out/label_1.ply")), 200u);  // a real surface for label 1
}

TEST_F(HostileInput, CslHoleWhoseParentIndexEqualsTheComponentCountIsAnError) {
  // The boundary of "parent < n_components": parent 2 of components 0..1.
  const Outcome out =
      run("reconstruct " + corpus("hole_parent_equals_count.csl") + " -o " + path("o.ply"));
  expect_error(out, {"hole_parent_equals_count.csl", "component 1", "names component 2",
                     "components are 0..1"});
}

// --- Messages that blamed the wrong thing. ---

TEST_F(HostileInput, CoordinatesOf1e200AreBlamedOnTheUnitsNotOnTooFewPoints) {
  Outcome out = run("reconstruct " + corpus("coordinates_1e200.slices.json") + " -o " + path("o"));
  expect_error(out, {"coordinates_1e200.slices.json", "slice 0, region 0", "point 0",
                     "beyond 1e12 mm", "check the units"});
  EXPECT_EQ(out.output.find("fewer than 3 distinct points"), std::string::npos) << out.output;
  out = run("reconstruct " + corpus("coordinate_1e200.csl") + " -o " + path("o"));
  expect_error(out, {"coordinate_1e200.csl", "line 6", "plane 1, vertex 1", "beyond 1e12 mm"});
}

TEST_F(HostileInput, AHundredThousandDigitNumberIsQuotedShort) {
  const std::string digits(100000, '9');
  std::ofstream(path("n.slices.json"))
      << R"({"format": "sonoshape-slices", "version": )" << digits << R"(, "slices": []})";
  std::ofstream(path("n.csl")) << "CSLC\n1 " << digits << "\n";
  for (const std::string name : {"n.slices.json", "n.csl"}) {
    const Outcome out = run("reconstruct " + path(name) + " -o " + path("o"));
    expect_error(out, {name, "(100000 characters)"});
    EXPECT_LT(out.output.size(), 1000u) << name;
  }
}

TEST_F(HostileInput, ABadPerFrameProbePoseIsBlamedOnTheFrameNotTheCalibration) {
  simulate_sweep();
  const std::string sweep =
      patched_sweep("pose.igs.mha", "Seq_Frame0001_ProbeToTrackerTransform = [^\n]*",
                    "Seq_Frame0001_ProbeToTrackerTransform = 1 2 3");
  const Outcome out = run("segment " + sweep + " -o " + path("s.json"));
  expect_error(out, {"pose.igs.mha", "frame 1: ProbeToTrackerTransform is not 16 numbers"});
  EXPECT_EQ(out.output.find("calibration"), std::string::npos) << out.output;
}

// --- Silent wrong output: now a clear error or the right result. ---

TEST_F(HostileInput, AnEmptySliceListIsAnErrorNotAnEmptySuccess) {
  const Outcome out = run("reconstruct " + corpus("no_slices.slices.json") + " -o " + path("o"));
  expect_error(out, {"no_slices.slices.json", "slices", "no slice"});
}

TEST_F(HostileInput, BoundsOf1e308AreRefusedNamingBounds) {
  const Outcome out = run("reconstruct " + corpus("bounds_1e308.slices.json") + " -o " + path("o"));
  expect_error(out, {"bounds_1e308.slices.json", "bounds", "leave bounds out"});
}

TEST_F(HostileInput, AllUnknownSlicesAreAnErrorNotSilence) {
  const Outcome out = run("reconstruct " + corpus("all_unknown.slices.json") + " -o " + path("o"));
  expect_error(out, {"all_unknown.slices.json", "no slice has a region of a material"});
  EXPECT_FALSE(fs::exists(path("o")));
}

TEST_F(HostileInput, UnitsOtherThanMillimetresAreRefused) {
  for (const std::string name : {"units_m.slices.json", "units_furlongs.slices.json"}) {
    const Outcome out = run("reconstruct " + corpus(name) + " -o " + path("o"));
    expect_error(out, {name, "units", "millimetres", "\"units\": \"mm\""});
  }
}

TEST_F(HostileInput, EvaluateGivesNoIoUOfOneForACube1e15Away) {
  const Outcome out = run("evaluate --recon " + corpus("cube_1e15_away.obj") +
                          " --truth 1:" + corpus("cube.obj") + " --json " + path("e.json"));
  ASSERT_EQ(out.exit_code, 0) << out.output;
  EXPECT_NE(out.output.find("IoU is undefined"), std::string::npos) << out.output;
  const auto scores = nlohmann::json::parse(file_text(path("e.json")));
  const auto& iou = scores["labels"][0]["iou"];
  EXPECT_TRUE(iou.is_null() || iou.get<double>() < 0.5) << scores.dump();
}

TEST_F(HostileInput, EvaluateCallsAMeshOfZeroAreaTrianglesUnhealthy) {
  const Outcome out = run("evaluate --recon " + corpus("zero_area.obj") +
                          " --truth 1:" + corpus("cube.obj") + " --json " + path("e.json"));
  ASSERT_EQ(out.exit_code, 0) << out.output;
  const auto scores = nlohmann::json::parse(file_text(path("e.json")));
  const auto& health = scores["labels"][0]["health"];
  EXPECT_EQ(health["degenerate_triangles"], 4) << scores.dump();
  EXPECT_EQ(health["closed_manifold_oriented"], false) << scores.dump();
}

TEST_F(HostileInput, SegmentRefusesOrientationXYZ) {
  simulate_sweep();
  const std::string sweep = patched_sweep("xyz.igs.mha", "UltrasoundImageOrientation = MFA",
                                          "UltrasoundImageOrientation = XYZ");
  const Outcome out = run("segment " + sweep + " -o " + path("s.json"));
  expect_error(out, {"xyz.igs.mha", "UltrasoundImageOrientation = 'XYZ'", "MF, MN, UF or UN"});
}

TEST_F(HostileInput, SegmentRefusesASweepWhoseFramesAreAllInvalid) {
  simulate_sweep();
  const std::string sweep = patched_sweep("inv.igs.mha", "ProbeToTrackerTransformStatus = OK",
                                          "ProbeToTrackerTransformStatus = INVALID");
  const Outcome out = run("segment " + sweep + " -o " + path("s.json"));
  expect_error(out, {"inv.igs.mha", "INVALID pose: 8", "nothing written"});
  EXPECT_FALSE(fs::exists(path("s.json")));
}

TEST_F(HostileInput, SegmentRefusesANaNTimestampNamingTheFrame) {
  simulate_sweep();
  const std::string sweep = patched_sweep("nan.igs.mha", "Seq_Frame0003_Timestamp = [0-9.e+-]+",
                                          "Seq_Frame0003_Timestamp = nan");
  const Outcome out = run("segment " + sweep + " -o " + path("s.json"));
  expect_error(out, {"nan.igs.mha", "frame 3: Timestamp = 'nan'", "seconds"});
}

TEST_F(HostileInput, SegmentRefusesANonRigidPoseNamingFrameAndTransform) {
  simulate_sweep();
  // Frame 2's pose scaled by 2: its first row's rotation entries doubled is enough.
  const std::string sweep = patched_sweep(
      "scaled.igs.mha", "Seq_Frame0002_ProbeToTrackerTransform = ([-0-9.e]+) ([-0-9.e]+) ",
      "Seq_Frame0002_ProbeToTrackerTransform = 2 0.5 ");
  const Outcome out = run("segment " + sweep + " -o " + path("s.json"));
  expect_error(out, {"scaled.igs.mha", "frame 2: ProbeToTrackerTransform", "not a rotation",
                     "TransformStatus = INVALID"});
}

TEST_F(HostileInput, SegmentRefusesACalibrationFileWithTwoConflictingTransforms) {
  simulate_sweep();
  std::string xml = file_text(path("sw.plus.xml"));
  const std::smatch found = [&] {
    std::smatch m;
    std::regex_search(xml, m, std::regex("    <Transform From=\"Image\"[^\n]*\n"));
    return m;
  }();
  ASSERT_FALSE(found.empty()) << xml;
  const std::string first = found.str();
  // The same transform with another pixel spacing: two calibrations, which is right unknown.
  const std::string second =
      std::regex_replace(first, std::regex("Matrix=\"[-0-9.e]+ "), "Matrix=\"3 ");
  ASSERT_NE(first, second);
  xml.replace(static_cast<std::size_t>(found.position()), first.size(), first + second);
  std::ofstream(path("two.plus.xml")) << xml;
  const Outcome out = run("segment " + path("sw.igs.mha") + " --calibration " +
                          path("two.plus.xml") + " -o " + path("s.json"));
  expect_error(out, {"two.plus.xml", "defines ImageToProbe twice with different matrices",
                     "delete the other"});
}

// Issue 40: `scan --source replay:` accepted mirrored, projective and 1e13 mm poses that
// `segment` refuses. One check serves both: each command refuses each pose, naming the frame.
TEST_F(HostileInput, ReplayAndSegmentRefuseTheSamePoses) {
  simulate_sweep();
  const struct {
    const char* name;
    const char* matrix;
    const char* problem;
  } poses[] = {{"mirrored", "-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "not a rotation"},
               {"projective", "1 0 0 0 0 1 0 0 0 0 1 0 0 0.1 0 1", "last row is not 0 0 0 1"},
               {"far", "1 0 0 1e13 0 1 0 0 0 0 1 0 0 0 0 1", "translation is 1e+13 mm"}};
  for (const auto& pose : poses) {
    const std::string sweep = patched_sweep(
        std::string(pose.name) + ".igs.mha", "Seq_Frame0002_ProbeToTrackerTransform = [^\n]+",
        std::string("Seq_Frame0002_ProbeToTrackerTransform = ") + pose.matrix);
    const Outcome segment = run("segment " + sweep + " -o " + path("s.json"));
    expect_error(segment, {sweep, "frame 2: ProbeToTrackerTransform", pose.problem});
    const Outcome scan = run("scan --source replay:" + sweep + " --fast -o " +
                             path(std::string("scan_") + pose.name));
    expect_error(scan, {sweep, "frame 2: ProbeToTrackerTransform", pose.problem});
  }
}

// --- Option values (issue 40, silent wrong output and unclear messages). ---

// Every number option of every command refuses "nan" naming the option, at once: CLI11's range
// checks let NaN through (every comparison with it is false), so that `slice --unknown-radius
// nan` died of SIGFPE, `simulate --latency-ms nan` wrote a sweep and exited 0 and `view
// --duration nan` never stopped. A negative value for a positive option is refused without the
// 309 digits of CLI11's open bound. The options are read from each command's --help, so that a
// new one is checked too.
TEST_F(HostileInput, EveryNumberOptionRefusesNanAndNegativesNamingIt) {
  const Outcome top = run("--help");
  const std::string subcommands = top.output.substr(top.output.find("Subcommands:"));
  const std::regex command_line(R"(\n  ([a-z]+) )");
  const std::regex number_option(R"((--[a-z0-9-]+) FLOAT([^ \n]*)(?: x ([0-9]+))?)");
  int checked = 0;
  for (std::sregex_iterator c(subcommands.begin(), subcommands.end(), command_line), end; c != end;
       ++c) {
    const std::string command = (*c)[1];
    const std::string help = run(command + " --help").output;
    for (std::sregex_iterator o(help.begin(), help.end(), number_option); o != end; ++o) {
      const std::string option = (*o)[1];
      const std::string type = (*o)[2];
      const int count = (*o)[3].matched ? std::stoi((*o)[3]) : 1;
      for (const std::string value : {"nan", "-1"}) {
        if (value == "-1" && type.find("POSITIVE") == std::string::npos &&
            type.find("NONNEGATIVE") == std::string::npos)
          continue;
        std::string arguments = command + " " + option;
        for (int i = 0; i < count; ++i) arguments += " " + value;
        SCOPED_TRACE(arguments);
        const Outcome out = run(arguments, 10.0);
        EXPECT_NE(out.exit_code, 0) << out.output;
        EXPECT_NE(out.exit_code, -1) << "killed (a crash or no end): " << out.output;
        EXPECT_NE(out.output.find(option), std::string::npos) << out.output;
        EXPECT_NE(out.output.find("'" + value + "' is not a"), std::string::npos) << out.output;
        EXPECT_EQ(out.output.find("1797693"), std::string::npos) << out.output;
        ++checked;
      }
    }
  }
  std::cout << checked << " option values refused\n";
  EXPECT_GE(checked, 60);  // scan, simulate, slice, listen, view
}

}  // namespace
}  // namespace hostile_input_test
