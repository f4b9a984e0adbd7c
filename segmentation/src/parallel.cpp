#include "parallel.hpp"

#if defined(__SANITIZE_THREAD__)
#include <memory>
#include <mutex>
#include <opencv2/core/parallel/backend/parallel_for.tbb.hpp>
#endif

namespace sonoshape::segmentation::detail {

void use_instrumented_parallel_backend() {
#if defined(__SANITIZE_THREAD__)
  static std::once_flag once;
  std::call_once(once, [] {
    cv::parallel::setParallelForBackend(std::make_shared<cv::parallel::tbb::ParallelForBackend>());
  });
#endif
}

#if defined(__SANITIZE_THREAD__)
namespace {
// Before main, so that OpenCV's own loops (its filters' and conversions') run on it too.
const bool kInstrumentedBackend = (use_instrumented_parallel_backend(), true);
}  // namespace
#endif

}  // namespace sonoshape::segmentation::detail
