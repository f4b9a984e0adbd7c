#pragma once
// Who may read the mesh stream (docs/formats/mesh-stream.md, "Who may read the stream"): ZeroMQ
// CURVE keys in files, and which endpoints other machines can reach.
#include <filesystem>
#include <optional>
#include <string>

#include "sonoshape/core/status.hpp"

namespace sonoshape::publish {

/// A CURVE key pair, each key in Z85 text (40 characters, 32 bytes).
struct CurveKeyPair {
  std::string public_key;
  std::string secret_key;
};

/// Ok when this libzmq supports CURVE (zmq_has("curve")); otherwise an error saying how to get
/// a libzmq built with libsodium.
Status curve_available();

/// A fresh key pair from libzmq (zmq_curve_keypair). Fails without CURVE support.
Result<CurveKeyPair> generate_curve_keypair();

/// The public key of a Z85 secret key (zmq_curve_public). Fails for a key that is not 40 Z85
/// characters, or without CURVE support.
Result<std::string> curve_public_key_of(const std::string& secret_key);

/// Writes `base`.key (the secret key, mode 0600, created only if absent) and `base`.pub (the
/// public key) in the key file format: '#' comment lines, then one line of 40 Z85 characters.
/// Refuses to replace an existing file. Errors name the file and the fix.
Status write_curve_keypair(const std::filesystem::path& base, const CurveKeyPair& keys);

/// Reads one key file (`what`: "secret" or "public", for the messages and to refuse the other
/// kind of file). Errors name the file and what is wrong: missing, no key line, more than one,
/// wrong length, a character outside Z85, a file of the other kind. A secret key file that
/// others may read or write is still read, with a warning (secret_key_file_exposure).
Result<std::string> read_curve_key(const std::filesystem::path& file, const std::string& what);

/// Why a secret key file is exposed, when its mode lets its group or others read or write it
/// (they could copy the scan's identity, or replace it with theirs): a warning naming the file,
/// its mode and the fix (chmod 600). None for a private file or one that cannot be examined.
std::optional<std::string> secret_key_file_exposure(const std::filesystem::path& file);

/// Whether only this machine can reach `endpoint`: ipc://, inproc://, or tcp on 127.0.0.0/8,
/// ::1 or localhost. False for every other tcp host (an interface, "*", 0.0.0.0, another
/// address) and other network transports. Text that is no endpoint at all ("127.0.0.1:5556")
/// counts as local: the bind then reports it as invalid.
bool is_local_endpoint(const std::string& endpoint);

}  // namespace sonoshape::publish
