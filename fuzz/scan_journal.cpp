// Fuzz target: the keyframe journal reader that `scan --resume DIR` runs on DIR/scan.journal
// (docs/formats/scan-journal.md), a file anyone who can write the scan's folder can craft.
//
// Input: either a whole journal file (it starts with the magic "SNSHJRNL"), or the JSON payloads
// of its records separated by 0xFF bytes (a byte no JSON text holds), which the target wraps in
// the header and in records with the right lengths and CRC-32s, so that mutations reach the
// records' content instead of stopping at the checksum. A record whose length is prefixed by
// 0xFE keeps a wrong CRC (a torn or corrupt record in the middle or at the end).
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "fuzz_support.hpp"
#include "sonoshape/scan/journal.hpp"

namespace {

void put_u32(std::string& out, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xFFu));
}

std::string journal_of_records(std::string_view input) {
  std::string file("SNSHJRNL", 8);
  put_u32(file, 1);  // version
  put_u32(file, 0);
  std::size_t at = 0;
  while (at <= input.size()) {
    const std::size_t end = std::min(input.find('\xFF', at), input.size());
    std::string_view payload = input.substr(at, end - at);
    const bool corrupt = !payload.empty() && payload.front() == '\xFE';
    if (corrupt) payload.remove_prefix(1);
    put_u32(file, static_cast<std::uint32_t>(payload.size()));
    const auto crc = static_cast<std::uint32_t>(::crc32(
        0L, reinterpret_cast<const Bytef*>(payload.data()), static_cast<uInt>(payload.size())));
    put_u32(file, corrupt ? crc ^ 1u : crc);
    file += payload;
    at = end + 1;
  }
  return file;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  const std::string input = sonoshape::fuzz::as_string(data, size);
  const std::string file = input.rfind("SNSHJRNL", 0) == 0 ? input : journal_of_records(input);
  const auto path = sonoshape::fuzz::write_scratch_file(file, ".journal");
  auto contents = sonoshape::scan::read_journal(path);
  // What reads is whole: the valid bytes lie within the file.
  if (contents && contents->valid_bytes > file.size()) __builtin_trap();
  sonoshape::fuzz::explain(contents ? std::to_string(contents->keyframes.size()) + " keyframes" +
                                          (contents->torn_tail ? ", torn tail" : "") +
                                          (contents->finished ? ", finished" : "")
                                    : contents.message());
  return 0;
}
