#include <gtest/gtest.h>

#include <cstdlib>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/kernels/opencl.hpp"

namespace sonoshape::kernels {
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
    const auto device = open_device(parse_device_spec("opencl:" + std::to_string(info.platform) + ":" +
                                                      std::to_string(info.device)));
    ASSERT_NE(device, nullptr);
    EXPECT_EQ(device->info().device_name, info.device_name);
  }
  if (!any) GTEST_SKIP() << "no OpenCL device with fp64: " << (error.empty() ? "none listed" : error);
}

}  // namespace
}  // namespace sonoshape::kernels
