// CURVE keys in files, and the loopback test behind --allow-remote.
#include "sonoshape/publish/curve.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zmq.h>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::publish {
namespace {

constexpr std::size_t kZ85KeyChars = 40;
// The 85 characters of Z85 (ZeroMQ RFC 32).
constexpr std::string_view kZ85Alphabet =
    "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-:+=^!/*?&<>()[]{}@%$#";

std::string key_file_text(const std::string& what, const std::string& key) {
  std::string text = "# sonoshape CURVE " + what + " key (Z85, docs/formats/mesh-stream.md)\n";
  if (what == "secret") text += "# keep it private: whoever holds it can impersonate the scan\n";
  return text + key + "\n";
}

// Creates `path` with `mode` (never replacing a file) and writes `text`.
Status write_new_file(const std::filesystem::path& path, const std::string& text, mode_t mode) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
  if (fd < 0) {
    if (errno == EEXIST)
      return Status::error("cannot write " + path.string() +
                           ": it exists already; remove it or choose another name (-o)");
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; check the folder");
  }
  const ssize_t written = ::write(fd, text.data(), text.size());
  const bool ok = written == static_cast<ssize_t>(text.size()) && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) return Status::error("cannot write " + path.string() + "; check the disk");
  return Status::ok();
}

std::string trimmed(const std::string& line) {
  const std::size_t first = line.find_first_not_of(" \t\r");
  if (first == std::string::npos) return {};
  return line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
}

bool is_loopback_host(const std::string& host) {
  if (host == "localhost" || host == "::1") return true;
  // 127.0.0.0/8: four decimal numbers, the first 127.
  if (host.rfind("127.", 0) != 0) return false;
  int dots = 0;
  for (char c : host) {
    if (c == '.')
      ++dots;
    else if (c < '0' || c > '9')
      return false;
  }
  return dots == 3;
}

}  // namespace

Status curve_available() {
  if (zmq_has("curve")) return Status::ok();
  return Status::error(
      "this libzmq has no CURVE security (it was built without libsodium): install a libzmq "
      "built with libsodium (Debian: libzmq5 from the distribution), or publish on loopback "
      "only");
}

Result<CurveKeyPair> generate_curve_keypair() {
  if (Status available = curve_available(); !available) return available;
  std::array<char, kZ85KeyChars + 1> public_key{};
  std::array<char, kZ85KeyChars + 1> secret_key{};
  if (zmq_curve_keypair(public_key.data(), secret_key.data()) != 0)
    return Status::error(std::string("cannot make a CURVE key pair: ") + zmq_strerror(zmq_errno()));
  return CurveKeyPair{public_key.data(), secret_key.data()};
}

Result<std::string> curve_public_key_of(const std::string& secret_key) {
  if (Status available = curve_available(); !available) return available;
  std::array<char, kZ85KeyChars + 1> public_key{};
  if (secret_key.size() != kZ85KeyChars ||
      zmq_curve_public(public_key.data(), secret_key.c_str()) != 0)
    return Status::error("not a CURVE secret key: expected 40 Z85 characters");
  return std::string(public_key.data());
}

Status write_curve_keypair(const std::filesystem::path& base, const CurveKeyPair& keys) {
  const std::filesystem::path secret_path = base.string() + ".key";
  const std::filesystem::path public_path = base.string() + ".pub";
  if (std::filesystem::exists(public_path))
    return Status::error("cannot write " + public_path.string() +
                         ": it exists already; remove it or choose another name (-o)");
  if (Status written = write_new_file(secret_path, key_file_text("secret", keys.secret_key), 0600);
      !written)
    return written;
  return write_new_file(public_path, key_file_text("public", keys.public_key), 0644);
}

std::optional<std::string> secret_key_file_exposure(const std::filesystem::path& file) {
  struct stat info {};
  if (::stat(file.c_str(), &info) != 0) return std::nullopt;
  const mode_t shared = info.st_mode & (S_IRWXG | S_IRWXO);
  if (shared == 0) return std::nullopt;
  char mode[8];
  std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(info.st_mode & 07777));
  const bool written = (shared & (S_IWGRP | S_IWOTH)) != 0;
  const bool read = (shared & (S_IRGRP | S_IROTH)) != 0;
  const std::string how = read && written ? "read and change" : written ? "change" : "read";
  return "the CURVE secret key " + file.string() + " has mode " + mode + ": other users of this " +
         "machine can " + how + " it (whoever holds the key can pose as the scan); make it " +
         "private: chmod 600 " + file.string();
}

Result<std::string> read_curve_key(const std::filesystem::path& file, const std::string& what) {
  const std::string other = what == "secret" ? "public" : "secret";
  const std::string fix = what == "secret" ? "give the NAME.key file that `sonoshape keys -o NAME` "
                                             "wrote"
                                           : "give the scan's NAME.pub file (from `sonoshape keys "
                                             "-o NAME`)";
  Result<std::string> bytes = read_input_file(file, "the CURVE " + what + " key");
  if (!bytes) return Status::error(bytes.message() + "; " + fix);
  // Editors on Windows start UTF-8 files with a byte-order mark: not part of the key.
  constexpr std::string_view kUtf8Bom = "\xEF\xBB\xBF";
  if (std::string_view(*bytes).starts_with(kUtf8Bom)) bytes->erase(0, kUtf8Bom.size());
  std::istringstream in(std::move(*bytes));
  std::string line;
  std::string key;
  int number = 0;
  int key_line = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::string text = trimmed(line);
    if (text.empty()) continue;
    if (text[0] == '#') {
      if (text.find(other + " key") != std::string::npos)
        return Status::error(file.string() + " holds a CURVE " + other + " key, not a " + what +
                             " key; " + fix);
      continue;
    }
    if (!key.empty())
      return Status::error(file.string() + " line " + std::to_string(number) +
                           ": a second key line (line " + std::to_string(key_line) +
                           " is the first); a key file holds one key; " + fix);
    key = text;
    key_line = number;
    // A 100000-character line is not worth quoting back: its length says enough.
    if (key.size() > 4 * kZ85KeyChars) break;
  }
  if (key.empty())
    return Status::error(file.string() + " holds no key line (one line of 40 Z85 characters); " +
                         fix);
  const std::string where = file.string() + " line " + std::to_string(key_line);
  if (key.size() != kZ85KeyChars)
    return Status::error(where + ": the CURVE " + what + " key has " + std::to_string(key.size()) +
                         " characters, a Z85 key has 40; " + fix);
  if (const std::size_t bad = key.find_first_not_of(kZ85Alphabet); bad != std::string::npos)
    return Status::error(where + ": character " + std::to_string(bad + 1) +
                         " of the key is not Z85 (ZeroMQ RFC 32); " + fix);
  std::array<std::uint8_t, 32> binary{};
  if (zmq_z85_decode(binary.data(), key.c_str()) == nullptr)
    return Status::error(where + ": the key does not decode as Z85; " + fix);
  // Used all the same (the user may know the machine is theirs alone), but never silently.
  if (what == "secret")
    if (const auto exposed = secret_key_file_exposure(file)) log_warning(*exposed);
  return key;
}

bool is_local_endpoint(const std::string& endpoint) {
  const std::size_t separator = endpoint.find("://");
  if (separator == std::string::npos) return true;  // no endpoint: the bind says so
  const std::string scheme = endpoint.substr(0, separator);
  if (scheme == "ipc" || scheme == "inproc") return true;
  const std::string rest = endpoint.substr(separator + 3);
  std::string host;
  if (!rest.empty() && rest.front() == '[')
    host = rest.substr(1, rest.find(']') == std::string::npos ? 0 : rest.find(']') - 1);
  else
    host = rest.substr(0, rest.rfind(':'));  // npos: the whole text (no port)
  return is_loopback_host(host);
}

}  // namespace sonoshape::publish
