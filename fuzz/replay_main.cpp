// A plain main for the fuzz targets' sources outside libFuzzer (any compiler): calls
// LLVMFuzzerTestOneInput on every file of the folders (or files) named on the command line, so
// that the seeds and every input a fuzzer once found run as a regression test in the default
// suite. A crash or a sanitizer report fails the test; an error Status from a reader does not.
#include <sys/resource.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

// ASan and TSan map terabytes of shadow memory, which an address-space limit would refuse.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kShadowMemory = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool kShadowMemory = true;
#else
constexpr bool kShadowMemory = false;
#endif
#else
constexpr bool kShadowMemory = false;
#endif

// libFuzzer stops an input at 2 GB (-rss_limit_mb=2048); here an address-space limit does, so
// that an input that once allocated without bound fails as std::bad_alloc instead of taking the
// machine's memory. Not under a sanitizer with shadow memory (see above).
void limit_memory() {
  if (kShadowMemory) return;
  const rlim_t limit = rlim_t{4} << 30;
  const rlimit value{limit, limit};
  setrlimit(RLIMIT_AS, &value);
}

int replay(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::cerr << file.string() << ": cannot be read\n";
    return 1;
  }
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  std::cerr << "replaying " << file.string() << " (" << bytes.size() << " bytes)\n";
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  limit_memory();
  int failures = 0;
  std::size_t count = 0;
  for (int i = 1; i < argc; ++i) {
    const std::filesystem::path arg = argv[i];
    if (!std::filesystem::is_directory(arg)) {
      // A folder without findings yet need not exist; a named file must.
      if (std::filesystem::exists(arg)) {
        failures += replay(arg);
        ++count;
      }
      continue;
    }
    std::vector<std::filesystem::path> files;
    for (const auto& entry : std::filesystem::directory_iterator(arg)) {
      if (entry.is_regular_file()) files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());  // the same order on every run
    for (const auto& file : files) {
      failures += replay(file);
      ++count;
    }
  }
  if (count == 0) {
    std::cerr << "no inputs found in the folders given\n";
    return 1;
  }
  std::cerr << count << " inputs replayed\n";
  return failures == 0 ? 0 : 1;
}
