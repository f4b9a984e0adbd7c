// The `sonoshape` command end to end: slice a bundled model, reconstruct, evaluate.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/testing/command.hpp"

namespace end_to_end_test {
namespace {

namespace fs = std::filesystem;

// Each test's command output goes to one log file in the temp directory.
sonoshape::testing::CommandResult run(const std::string& arguments) {
  const fs::path log =
      fs::temp_directory_path() /
      ("sonoshape_e2e_" +
       std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
       std::to_string(::getpid()) + ".log");
  return sonoshape::testing::run_command(SONOSHAPE_BINARY, arguments, log);
}

class EndToEnd : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sonoshape_e2e_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
            std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string model(const std::string& name) {
    return (fs::path(SONOSHAPE_DATA_DIR) / "models" / name).string();
  }

  fs::path dir_;
};

// Checks the goals of the offline engine on one evaluated set.
void expect_goals(const nlohmann::json& scores) {
  ASSERT_FALSE(scores["labels"].empty());
  for (const auto& s : scores["labels"]) {
    SCOPED_TRACE("label " + std::to_string(s["label"].get<int>()));
    EXPECT_TRUE(s["health"]["closed_manifold_oriented"].get<bool>());
    EXPECT_GT(s["iou"].get<double>(), s["baseline_iou"].get<double>());
    EXPECT_GT(s["iou"].get<double>(), 0.8);  // sanity floor; the real goal is the baseline
    EXPECT_LE(s["contour_mean_percent"].get<double>(), 0.5);
    EXPECT_LE(s["contour_max_percent"].get<double>(), 2.0);
  }
}

TEST_F(EndToEnd, SliceReconstructEvaluateOneLabel) {
  auto r = run("slice --mesh 1:" + model("spot.obj") +
               ":spot --planes random --count 24 --seed 3 --size-mm 150 -o " +
               path("spot.slices.json") + " --truth " + path("truth"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + path("spot.slices.json") + " -o " + path("spot.ply") + " --stats " +
          path("stats.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream stats_file(path("stats.json"));
  const nlohmann::json stats = nlohmann::json::parse(stats_file);
  for (const char* key :
       {"arrangement_s", "face_images_s", "field_s", "smoothing_s", "mesh_s", "total_s", "slices",
        "cells", "faces", "field_evaluations", "triangles", "peak_rss_mb"})
    EXPECT_TRUE(stats.contains(key)) << key;
  EXPECT_EQ(stats["slices"].get<int>(), 24);
  r = run("evaluate --recon " + path("spot.ply") + " --truth 1:" + path("truth/label_1.ply") +
          " --slices " + path("spot.slices.json") + " --json " + path("eval.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream eval_file(path("eval.json"));
  expect_goals(nlohmann::json::parse(eval_file));
}

TEST_F(EndToEnd, TwoLabelsThroughCsl) {
  auto r = run("slice --mesh 1:" + model("spot.obj") + ":spot --mesh 2:" + model("rocker-arm.obj") +
               ":rocker --planes orthogonal --count 27 --seed 2 --size-mm 120 -o " +
               path("pair.csl") + " --truth " + path("truth"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + path("pair.csl") + " -o " + path("out"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(path("out/label_1.ply")));
  EXPECT_TRUE(fs::exists(path("out/label_2.ply")));
  r = run("evaluate --recon " + path("out") + " --truth 1:" + path("truth/label_1.ply") +
          " --truth 2:" + path("truth/label_2.ply") + " --slices " + path("pair.csl") + " --json " +
          path("eval.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream eval_file(path("eval.json"));
  expect_goals(nlohmann::json::parse(eval_file));
}

TEST_F(EndToEnd, MalformedInputGivesAClearErrorAndNoMesh) {
  {
    std::ofstream bad(path("bad.slices.json"));
    bad << R"({"format": "sonoshape-slices", "version": 1, "slices": [
      {"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0],
       "regions": [{"label": 1, "polygon": [[0, 0], [1, 0], [2, 0]]}]}]})";
  }
  const auto r = run("reconstruct " + path("bad.slices.json") + " -o " + path("bad.ply"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("bad.slices.json"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("slice 0"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("zero area"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("bad.ply")));
}

TEST_F(EndToEnd, ReconstructWritesMeshesOnlyForTheMaterialsThatOccur) {
  // nLabels = 20 with materials 1-3 used (tests/data/real_input/nested_materials.csl).
  const std::string csl =
      std::string(SONOSHAPE_DATA_DIR) + "/../tests/data/real_input/nested_materials.csl";
  const auto r =
      run("reconstruct " + csl + " -o " + path("out") + " --depth 5 --stats " + path("stats.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(path("out")))
    files.push_back(entry.path().filename().string());
  std::sort(files.begin(), files.end());
  EXPECT_EQ(files, (std::vector<std::string>{"label_1.ply", "label_2.ply", "label_3.ply"}));
  EXPECT_NE(r.output.find("materials 4..19 never occur"), std::string::npos) << r.output;
}

TEST_F(EndToEnd, StrictRefusesAContourThatWouldBeRepaired) {
  {
    std::ofstream bow_tie(path("bow_tie.slices.json"));
    bow_tie << R"({"format": "sonoshape-slices", "version": 1, "slices": [
      {"origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0],
       "regions": [{"label": 1, "polygon": [[0, 0], [1, 1], [1, 0], [0, 1]]}]}]})";
  }
  const auto r = run("reconstruct " + path("bow_tie.slices.json") + " -o " + path("bow_tie.ply") +
                     " --strict");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("slice 0, region 0 (label 1), outer ring: contour crosses itself"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("--strict"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("bow_tie.ply")));
}

TEST_F(EndToEnd, MissingInputAndHelp) {
  auto r = run("reconstruct " + path("nope.slices.json") + " -o " + path("x.ply"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("nope.slices.json"), std::string::npos) << r.output;
  r = run("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"reconstruct", "slice", "evaluate"})
    EXPECT_NE(r.output.find(sub), std::string::npos);
}

// The interpolation property of the paper (Section 4.6): smoothing leaves the octree nodes next
// to the input contours alone, so the surface keeps passing through the contours. The contour
// error with 8 smoothing passes stays at its level without smoothing (24 random slices of
// spot: 0.0634 % both); with the contour nodes smoothed too it rose (issue 27's surviving
// mutation: 0.30 % -> 0.52 % on another set), while the smoothing still changes the surface.
TEST_F(EndToEnd, AFileSizeLimitFailsEachCommandsWritesWithTheFileNamed) {
  // Under ulimit -f these commands died of SIGXFSZ without a word (only scan ignored it).
  ASSERT_EQ(run("simulate --frames 6 --width-px 160 --height-px 160 -q -o " + path("in.igs.mha"))
                .exit_code,
            0);
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  rlimit small = old;
  small.rlim_cur = 16 * 1024;  // above each command's log, below each command's output
  // The children inherit the limit and the default SIGXFSZ (which kills): the command itself
  // must ignore the signal. This process writes nothing while the limit holds.
  const auto previous = std::signal(SIGXFSZ, SIG_DFL);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const std::string example = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels.slices.json";
  const std::vector<std::pair<std::string, std::string>> commands = {
      {"reconstruct " + example + " -o " + path("out"), path("out") + "/label_1.ply"},
      {"slice --mesh 1:" + model("spot.obj") + " --planes random --count 40 --seed 1 -o " +
           path("cut.slices.json"),
       path("cut.slices.json")},
      {"simulate --frames 20 -o " + path("sweep.igs.mha"), path("sweep.igs.mha")},
      {"segment " + path("in.igs.mha") + " -o " + path("seg.slices.json"),
       path("seg.slices.json")}};
  std::vector<sonoshape::testing::CommandResult> results;
  for (const auto& [command, file] : commands) results.push_back(run(command + " -q"));
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, previous);
  for (std::size_t k = 0; k < commands.size(); ++k) {
    SCOPED_TRACE(commands[k].first);
    EXPECT_GT(results[k].exit_code, 0) << results[k].output;  // -1: killed by a signal
    EXPECT_NE(results[k].output.find("cannot write"), std::string::npos) << results[k].output;
    EXPECT_NE(results[k].output.find(commands[k].second), std::string::npos) << results[k].output;
  }
}

TEST_F(EndToEnd, SmoothingKeepsTheSurfaceOnTheContours) {
  auto r = run("slice --mesh 1:" + model("spot.obj") +
               ":spot --planes random --count 24 --seed 3 "
               "--size-mm 150 -o " +
               path("spot.slices.json") + " --truth " + path("truth"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto contour_scores = [&](int smooth) {
    const std::string mesh = path("spot" + std::to_string(smooth) + ".ply");
    auto rr = run("reconstruct " + path("spot.slices.json") + " -o " + mesh + " --smooth " +
                  std::to_string(smooth));
    EXPECT_EQ(rr.exit_code, 0) << rr.output;
    const std::string json = path("eval" + std::to_string(smooth) + ".json");
    rr = run("evaluate --recon " + mesh + " --truth 1:" + path("truth/label_1.ply") + " --slices " +
             path("spot.slices.json") + " --json " + json);
    EXPECT_EQ(rr.exit_code, 0) << rr.output;
    std::ifstream in(json);
    return nlohmann::json::parse(in)["labels"][0];
  };
  const auto raw = contour_scores(0);
  const auto smoothed = contour_scores(8);
  const double raw_mean = raw["contour_mean_percent"].get<double>();
  const double smoothed_mean = smoothed["contour_mean_percent"].get<double>();
  EXPECT_LE(smoothed_mean, 1.02 * raw_mean)
      << "raw " << raw_mean << " %, smoothed " << smoothed_mean;
  EXPECT_LE(smoothed["contour_max_percent"].get<double>(),
            1.02 * raw["contour_max_percent"].get<double>());
  // The smoothing did act: the surface away from the contours moved.
  EXPECT_NE(raw["mean_surface_distance_percent"].get<double>(),
            smoothed["mean_surface_distance_percent"].get<double>());
}

TEST_F(EndToEnd, BundledExampleReconstructs) {
  const std::string example = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels.slices.json";
  const auto r = run("reconstruct " + example + " -o " + path("out"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string truth = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels_truth/";
  const auto e = run("evaluate --recon " + path("out") + " --truth 1:" + truth +
                     "label_1.ply --truth 2:" + truth + "label_2.ply --slices " + example +
                     " --json " + path("eval.json"));
  ASSERT_EQ(e.exit_code, 0) << e.output;
  std::ifstream eval_file(path("eval.json"));
  expect_goals(nlohmann::json::parse(eval_file));
}

TEST_F(EndToEnd, OnlineReconstructionEmitsStepsAndEqualsOffline) {
  const std::string example = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels.slices.json";
  // The paper's field, whose online updates equal its one-shot reconstruction (the thin-plate
  // field's agree to its online tolerance: the next test).
  auto r =
      run("reconstruct " + example + " -o " + path("online") +
          " --field mean-value --depth 5 --online --emit-every 3 --stats " + path("online.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + example + " -o " + path("offline") + " --field mean-value --depth 5");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream stats_file(path("online.json"));
  const nlohmann::json stats = nlohmann::json::parse(stats_file);
  const std::size_t slices = stats["slices"].get<std::size_t>();
  ASSERT_EQ(stats["steps"].size(), slices);
  for (const auto& step : stats["steps"])
    for (const char* key : {"slice", "arrangement_s", "field_s", "smoothing_s", "mesh_s", "total_s",
                            "cells_changed", "field_evaluations"})
      EXPECT_TRUE(step.contains(key)) << key;
  EXPECT_TRUE(fs::exists(path("online/step_0003/label_1.ply")));
  EXPECT_FALSE(fs::exists(path("online/step_0001")));
  // The online engine ends with the same meshes as the one-shot reconstruction, which builds
  // its cells on demand: the same triangles, and vertices whose fields agree within 1e-9 may
  // round to neighbouring 32-bit floats in the PLY.
  for (const char* label : {"label_1.ply", "label_2.ply"}) {
    const auto a = sonoshape::read_mesh(path("online/") + label),
               b = sonoshape::read_mesh(path("offline/") + label);
    ASSERT_TRUE(a) << a.message();
    ASSERT_TRUE(b) << b.message();
    EXPECT_FALSE(a->triangles.empty());
    EXPECT_EQ(a->triangles, b->triangles) << label;
    ASSERT_EQ(a->vertices.size(), b->vertices.size()) << label;
    double worst_mm = 0.0;
    for (std::size_t v = 0; v < a->vertices.size(); ++v)
      worst_mm = std::max(worst_mm, (a->vertices[v] - b->vertices[v]).cwiseAbs().maxCoeff());
    EXPECT_LE(worst_mm, 1e-5) << label;  // float rounding of coordinates of tens of mm
  }
  r = run("reconstruct " + example + " -o " + path("x") + " --emit-every 2");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--online"), std::string::npos) << r.output;
}

// --field thin-plate through the command: online and offline agree to the online tolerance
// (not to the bit: the online solves start from the last solution); an unknown field is refused.
TEST_F(EndToEnd, ThinPlateFieldOnlineAndOfflineAgree) {
  const std::string example = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels.slices.json";
  auto r = run("reconstruct " + example + " -o " + path("online") +
               " --depth 5 --field thin-plate --online --stats " + path("online.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + example + " -o " + path("offline") +
          " --depth 5 --field thin-plate --stats " + path("offline.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream stats_file(path("offline.json"));
  const nlohmann::json stats = nlohmann::json::parse(stats_file);
  EXPECT_GT(stats["solve_iterations"].get<int>(), 0);
  EXPECT_GT(stats["solve_nodes"].get<int>(), 0);
  EXPECT_EQ(stats["cells"].get<int>(), 0);  // no arrangement
  for (const char* label : {"label_1.ply", "label_2.ply"}) {
    const auto a = sonoshape::read_mesh(path("online/") + label),
               b = sonoshape::read_mesh(path("offline/") + label);
    ASSERT_TRUE(a) << a.message();
    ASSERT_TRUE(b) << b.message();
    ASSERT_FALSE(a->triangles.empty());
    EXPECT_TRUE(sonoshape::check_mesh_health(*a).closed_manifold_oriented());
    EXPECT_NEAR(sonoshape::signed_volume(*a), sonoshape::signed_volume(*b),
                1e-3 * sonoshape::signed_volume(*b))
        << label;
  }
  r = run("reconstruct " + example + " -o " + path("x") + " --field harmonic");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("thin-plate"), std::string::npos) << r.output;
}

// --device: the OpenCL field (PoCL in CI) writes the same mesh file as the native CPU, byte for
// byte; `devices` lists it; a malformed or missing device is refused before any work.
TEST_F(EndToEnd, ReconstructOnOpenClWritesTheCpuMesh) {
  auto r = run("devices");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("Field evaluation (OpenCL):"), std::string::npos) << r.output;
  if (r.output.find("fp64, --device opencl:") == std::string::npos)
    GTEST_SKIP() << "no OpenCL device with fp64 (install pocl-opencl-icd):\n" << r.output;
  r = run("slice --mesh 1:" + model("spot.obj") +
          ":spot --planes random --count 12 --seed 2 --size-mm 150 -o " + path("spot.slices.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + path("spot.slices.json") + " --field mean-value --depth 6 -o " +
          path("cpu.ply") + " --device cpu");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run("reconstruct " + path("spot.slices.json") + " --field mean-value --depth 6 -o " +
          path("opencl.ply") + " --device opencl");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream a(path("cpu.ply"), std::ios::binary), b(path("opencl.ply"), std::ios::binary);
  const std::string bytes_a((std::istreambuf_iterator<char>(a)), std::istreambuf_iterator<char>());
  const std::string bytes_b((std::istreambuf_iterator<char>(b)), std::istreambuf_iterator<char>());
  EXPECT_GT(bytes_a.size(), 1000u);
  EXPECT_TRUE(bytes_a == bytes_b) << "the OpenCL mesh differs from the CPU's";
}

TEST_F(EndToEnd, AMalformedOrMissingDeviceIsRefusedWithTheFix) {
  const std::string reconstruct = "reconstruct " + std::string(SONOSHAPE_DATA_DIR) +
                                  "/examples/two_labels.slices.json -o " + path("x.ply") +
                                  " --field mean-value";
  auto r = run(reconstruct + " --device gpu");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("opencl:PLATFORM:DEVICE"), std::string::npos) << r.output;
  r = run(reconstruct + " --device opencl:9:9");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(r.output.find("no such OpenCL device") != std::string::npos ||
              r.output.find("no OpenCL") != std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(path("x.ply")));
}

// The thin-plate field (the default) has no OpenCL path: an explicit --device is refused with the
// fix, where running on the CPU instead would quietly not be what was asked for.
TEST_F(EndToEnd, ADeviceWithTheThinPlateFieldIsRefusedNamingTheMeanValueField) {
  const std::string example = std::string(SONOSHAPE_DATA_DIR) + "/examples/two_labels.slices.json";
  for (const std::string field : {"", " --field thin-plate"}) {
    SCOPED_TRACE(field);
    const auto r =
        run("reconstruct " + example + " -o " + path("x.ply") + field + " --device opencl");
    EXPECT_NE(r.exit_code, 0);
    EXPECT_NE(r.output.find("--field mean-value"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(path("x.ply")));
  }
  const auto r = run("reconstruct " + example + " -o " + path("cpu") + " --device cpu");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

}  // namespace
}  // namespace end_to_end_test
