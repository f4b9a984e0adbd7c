// Example: following a live scan's mesh stream from a program of your own (any ZeroMQ binding
// can; this one uses sonoshape's reference subscriber, which checks every message against
// docs/formats/mesh-stream.md). Joins late through the snapshot, then prints every message.
//
//   follow_stream [PUB_ENDPOINT [SNAPSHOT_ENDPOINT [SECONDS]]]
//       defaults: tcp://127.0.0.1:5556 tcp://127.0.0.1:5557 10
//
// Start a scan that publishes (`sonoshape scan --source sim:default --realtime`), then this.
// It stops after SECONDS, or when the scan reports that it is idle (finished).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <type_traits>
#include <variant>

#include "sonoshape/core/scan_state.hpp"
#include "sonoshape/publish/subscriber.hpp"

using namespace sonoshape;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  publish::SubscriberOptions options;
  options.endpoint = argc > 1 ? argv[1] : "tcp://127.0.0.1:5556";
  options.snapshot_endpoint = argc > 2 ? argv[2] : "tcp://127.0.0.1:5557";
  const double seconds = argc > 3 ? std::atof(argv[3]) : 10.0;
  // Fails when no publisher answers the snapshot request in time.
  Result<publish::MeshSubscriber> subscriber = publish::MeshSubscriber::connect(options);
  if (!subscriber) {
    std::fprintf(stderr, "%s\n", subscriber.message().c_str());
    return 1;
  }
  const auto stop = Clock::now() + std::chrono::duration<double>(seconds);
  int invalid = 0;
  while (Clock::now() < stop) {
    auto received = subscriber->receive(std::chrono::milliseconds(200));
    if (!received) {  // a message that breaks the format: named, then the stream goes on
      std::fprintf(stderr, "invalid message: %s\n", received.message().c_str());
      ++invalid;
      continue;
    }
    if (!*received) continue;  // nothing within 200 ms
    const publish::StreamMessage& message = **received;
    bool finished = false;
    std::visit(
        [&](const auto& body) {
          using Body = std::decay_t<decltype(body)>;
          if constexpr (std::is_same_v<Body, publish::MeshUpdate>) {
            std::printf("seq %llu %s: %zu vertices, %zu triangles\n",
                        static_cast<unsigned long long>(message.seq), message.topic().c_str(),
                        body.mesh.vertices.size(), body.mesh.triangles.size());
          } else if constexpr (std::is_same_v<Body, publish::StatusReport>) {
            std::printf("seq %llu status: %llu slices, state %s\n",
                        static_cast<unsigned long long>(message.seq),
                        static_cast<unsigned long long>(body.slices),
                        std::string(to_string(body.state)).c_str());
            // An error status reports a failure the scan carries on from; idle means done.
            finished = body.state == ScanState::kIdle;
          } else {
            std::printf("seq %llu %s\n", static_cast<unsigned long long>(message.seq),
                        message.topic().c_str());
          }
        },
        message.body);
    if (finished) break;
  }
  return invalid == 0 ? 0 : 1;
}
