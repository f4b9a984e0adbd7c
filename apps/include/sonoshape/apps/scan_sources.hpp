#pragma once
// The frame sources `sonoshape scan` offers, in one place: the registry of scan/ filled with
// every backend this build has (sim:, replay:, igtl:, v4l2:), each under its build option.
// Adding a source is one entry here and its opener.
#include <filesystem>
#include <string>

#include "sonoshape/apps/sim_scenario.hpp"
#include "sonoshape/scan/sources.hpp"

namespace sonoshape::apps {

/// The options of the simulated source (`sim:`), beside the request's common ones.
struct SimSourceOptions {
  SimScenarioOptions scenario;
  double duration_s = 20.0;  ///< length of the simulated sweep (s)
  double fail_after_s = -1;  ///< fault injection: the probe vanishes at this time (< 0: never)
  std::filesystem::path models_dir;  ///< bundled models of the built-in demo phantom
};

/// Every kind of source of this build; `sim` configures the simulated one.
scan::SourceRegistry scan_sources(const SimSourceOptions& sim = {});

/// scan_sources(sim).open(request).
Result<scan::ScanSource> open_scan_source(const scan::SourceRequest& request,
                                          const SimSourceOptions& sim = {});

/// `sim:PHANTOM_SPEC`: a simulated probe and tracker over the phantom of the spec (or the
/// built-in demo), label models learnt from a few rendered frames.
Result<scan::ScanSource> open_sim_source(const scan::SourceRequest& request,
                                         const SimSourceOptions& sim,
                                         const std::string& phantom_spec);

}  // namespace sonoshape::apps
