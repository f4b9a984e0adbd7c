#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/kernels/opencl.hpp"

namespace sonoshape::kernels::device_spec_test {
namespace {

TEST(DeviceSpec, ParsesEveryForm) {
  EXPECT_EQ(parse_device_spec("cpu").kind, DeviceSpec::Kind::cpu);
  EXPECT_EQ(parse_device_spec("auto").kind, DeviceSpec::Kind::automatic);
  const DeviceSpec any = parse_device_spec("opencl");
  EXPECT_EQ(any.kind, DeviceSpec::Kind::opencl);
  EXPECT_EQ(any.platform, -1);
  const DeviceSpec named = parse_device_spec("opencl:1:2");
  EXPECT_EQ(named.platform, 1);
  EXPECT_EQ(named.device, 2);
  EXPECT_EQ(named.text(), "opencl:1:2");
}

TEST(DeviceSpec, RejectsMalformedSpecsWithTheAcceptedForms) {
  for (const char* bad : {"gpu", "opencl:1", "opencl:a:0", "opencl:0:-1", "opencl:0:1x", ""}) {
    try {
      parse_device_spec(bad);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("opencl"), std::string::npos) << e.what();
    }
  }
}

TEST(DeviceSpec, OptionOverridesEnvironmentWhichOverridesDefault) {
  ::setenv("SONOSHAPE_DEVICE", "auto", 1);
  EXPECT_EQ(device_spec_from("").kind, DeviceSpec::Kind::automatic);
  EXPECT_EQ(device_spec_from("cpu").kind, DeviceSpec::Kind::cpu);
  ::setenv("SONOSHAPE_DEVICE", "nonsense", 1);
  EXPECT_THROW(device_spec_from(""), Error);
  ::unsetenv("SONOSHAPE_DEVICE");
  EXPECT_EQ(device_spec_from("").kind, DeviceSpec::Kind::cpu);
}

TEST(OpenClDevices, FieldProgramBuildsOnEveryFp64Device) {
  std::string error;
  const auto devices = list_devices(&error);
  bool any = false;
  for (const DeviceInfo& info : devices) {
    if (!info.fp64) continue;
    any = true;
    const auto device = open_device(parse_device_spec("opencl:" + std::to_string(info.platform) +
                                                      ":" + std::to_string(info.device)));
    ASSERT_NE(device, nullptr);
    EXPECT_EQ(device->info().device_name, info.device_name);
  }
  if (!any)
    GTEST_SKIP() << "no OpenCL device with fp64: " << (error.empty() ? "none listed" : error);
}

// auto: an fp64 GPU when one is listed, else nothing (the native CPU path).
TEST(OpenClDevices, AutoTakesAGpuOrTheCpu) {
  bool gpu = false;
  for (const DeviceInfo& info : list_devices()) gpu |= info.gpu && info.fp64;
  const auto device = open_device(parse_device_spec("auto"));
  EXPECT_EQ(device != nullptr, gpu);
  if (device) {
    EXPECT_TRUE(device->info().gpu);
  }
  EXPECT_EQ(open_device(parse_device_spec("cpu")), nullptr);
}

// The second start reads the program binary the first one stored under XDG_CACHE_HOME.
TEST(OpenClDevices, ProgramBinaryIsCachedAndReadBack) {
  std::string error;
  std::string spec;
  for (const DeviceInfo& info : list_devices(&error))
    if (info.fp64 && spec.empty())
      spec = "opencl:" + std::to_string(info.platform) + ":" + std::to_string(info.device);
  if (spec.empty())
    GTEST_SKIP() << "no OpenCL device with fp64: " << (error.empty() ? "none listed" : error);
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("sonoshape_kernels_cache_test_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  const char* old = std::getenv("XDG_CACHE_HOME");
  const std::string saved = old ? old : "";
  ::setenv("XDG_CACHE_HOME", dir.c_str(), 1);
  const bool first = open_device(parse_device_spec(spec))->program_from_cache();
  const bool second = open_device(parse_device_spec(spec))->program_from_cache();
  const bool stored = std::filesystem::exists(dir / "sonoshape" / "opencl") &&
                      !std::filesystem::is_empty(dir / "sonoshape" / "opencl");
  if (old)
    ::setenv("XDG_CACHE_HOME", saved.c_str(), 1);
  else
    ::unsetenv("XDG_CACHE_HOME");
  std::filesystem::remove_all(dir);
  EXPECT_FALSE(first);
  EXPECT_TRUE(second);
  EXPECT_TRUE(stored);
}

}  // namespace
}  // namespace sonoshape::kernels::device_spec_test
