// `sonoshape keys`: makes a CURVE key pair for the mesh stream (docs/formats/mesh-stream.md,
// "Who may read the stream"): NAME.key for `scan --curve-secret-key`, NAME.pub for the
// subscribers' --server-key.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>
#include <memory>

#include "commands.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/publish/curve.hpp"

namespace sonoshape::apps {
namespace {

int run_keys(const std::filesystem::path& base) {
  // An empty NAME, or one that ends in a folder ("keys/"), would write the hidden files .key and
  // .pub: a name is needed.
  const std::string name = base.filename().string();
  if (name.empty() || name == "." || name == "..") {
    std::cerr << "error: keys -o '" << base.string()
              << "' names no file: give NAME (or DIR/NAME) to write NAME.key and NAME.pub, e.g. "
                 "-o scanner\n";
    return 1;
  }
  Result<publish::CurveKeyPair> keys = publish::generate_curve_keypair();
  if (!keys) {
    std::cerr << "error: " << keys.message() << '\n';
    return 1;
  }
  if (Status written = publish::write_curve_keypair(base, *keys); !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  log_info("keys: wrote " + base.string() +
           ".key (secret, mode 0600: for scan "
           "--curve-secret-key) and " +
           base.string() +
           ".pub (public: for listen/view "
           "--server-key)");
  return 0;
}

}  // namespace

CommandRunner add_keys_command(CLI::App& app) {
  auto base = std::make_shared<std::filesystem::path>();
  app.add_option("-o,--output", *base,
                 "Writes NAME.key (the secret key, for scan --curve-secret-key; keep it private) "
                 "and NAME.pub (the public key, for listen/view --server-key); never replaces "
                 "a file")
      ->required();
  return [base] { return run_keys(*base); };
}

}  // namespace sonoshape::apps
