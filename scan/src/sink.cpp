#include "sonoshape/scan/sink.hpp"

#include <nlohmann/json.hpp>

namespace sonoshape::scan {
namespace {

nlohmann::json counters_json(const ScanCounters& c) {
  const DropCounts& d = c.dropped;
  return {{"frames_received", c.frames_received},
          {"frames_dropped", d.total()},
          {"dropped",
           {{"source", d.source},
            {"pose_missing", d.pose_missing},
            {"pose_invalid", d.pose_invalid},
            {"pose_gap", d.pose_gap},
            {"pose_extrapolation", d.pose_extrapolation},
            {"segmentation_behind", d.segmentation_behind},
            {"segmentation_failed", d.segmentation_failed},
            {"reconstruction_behind", d.reconstruction_behind},
            {"reconstruction_rejected", d.reconstruction_rejected}}},
          {"keyframes_skipped", c.keyframes_skipped},
          {"slices", c.slices},
          {"updates", c.updates},
          {"last_update_ms", c.last_update_ms}};
}

}  // namespace

std::string summary_json(const ScanSummary& summary) {
  nlohmann::json doc = counters_json(summary.counters);
  doc["stop_reason"] = to_string(summary.stop_reason);
  doc["frame_source"] = summary.frame_source;
  doc["pose_source"] = summary.pose_source;
  if (!summary.frame_source_losses.empty())
    doc["frame_source_losses"] = summary.frame_source_losses;
  doc["errors"] = summary.errors;
  doc["latency_s"] = {{"count", summary.latency.count},
                      {"p50", summary.latency.p50_s},
                      {"p95", summary.latency.p95_s},
                      {"max", summary.latency.max_s}};
  doc["update_ms"] = {{"median", summary.update_ms_median},
                      {"p95", summary.update_ms_p95},
                      {"max", summary.update_ms_max}};
  doc["duration_s"] = summary.duration_s;
  nlohmann::json listed = nlohmann::json::array();
  for (const RepairReport::Entry& e : summary.repairs.first)
    listed.push_back({{"frame", e.frame},
                      {"kind", e.repair.kind},
                      {"where", e.repair.where},
                      {"detail", e.repair.detail},
                      {"area_changed", e.repair.area_changed_mm2}});
  doc["repairs"] = {
      {"total", summary.repairs.total()}, {"by_kind", summary.repairs.counts}, {"first", listed}};
  doc["labels_without_mesh"] = summary.labels_without_mesh;
  if (summary.segmentation_scores)
    doc["segmentation_scores"] = nlohmann::json::parse(
        segmentation::comparison_json_text(*summary.segmentation_scores, summary.label_names));
  return doc.dump(2);
}

}  // namespace sonoshape::scan
