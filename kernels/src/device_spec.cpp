// --device and SONOSHAPE_DEVICE (with or without OpenCL in the build).
#include <cstdlib>
#include <string>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/kernels/opencl.hpp"

namespace sonoshape::kernels {
namespace {

int parse_index(const std::string& text, const std::string& spec) {
  std::size_t used = 0;
  int value = -1;
  try {
    value = std::stoi(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || value < 0)
    throw Error("device '" + spec + "': '" + text +
                "' is not an index; use cpu, auto, opencl or opencl:PLATFORM:DEVICE (indices as "
                "`sonoshape devices` lists them)");
  return value;
}

}  // namespace

std::string DeviceSpec::text() const {
  switch (kind) {
    case Kind::cpu:
      return "cpu";
    case Kind::automatic:
      return "auto";
    case Kind::opencl:
      break;
  }
  if (platform < 0) return "opencl";
  return "opencl:" + std::to_string(platform) + ":" + std::to_string(device);
}

DeviceSpec parse_device_spec(const std::string& text) {
  DeviceSpec spec;
  if (text == "cpu") return spec;
  if (text == "auto") {
    spec.kind = DeviceSpec::Kind::automatic;
    return spec;
  }
  if (text == "opencl") {
    spec.kind = DeviceSpec::Kind::opencl;
    return spec;
  }
  const std::string prefix = "opencl:";
  if (text.rfind(prefix, 0) == 0) {
    const std::string rest = text.substr(prefix.size());
    const std::size_t colon = rest.find(':');
    if (colon == std::string::npos)
      throw Error("device '" + text +
                  "': name both indices, opencl:PLATFORM:DEVICE (e.g. opencl:0:0)");
    spec.kind = DeviceSpec::Kind::opencl;
    spec.platform = parse_index(rest.substr(0, colon), text);
    spec.device = parse_index(rest.substr(colon + 1), text);
    return spec;
  }
  throw Error("device '" + text +
              "' is not known; use cpu, auto, opencl or opencl:PLATFORM:DEVICE");
}

DeviceSpec device_spec_from(const std::string& option) {
  if (!option.empty()) return parse_device_spec(option);
  const char* env = std::getenv("SONOSHAPE_DEVICE");
  if (env != nullptr && *env != '\0') {
    try {
      return parse_device_spec(env);
    } catch (const Error& e) {
      throw Error(std::string("SONOSHAPE_DEVICE: ") + e.what());
    }
  }
  return DeviceSpec{};
}

}  // namespace sonoshape::kernels
