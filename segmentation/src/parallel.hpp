#pragma once
// The segmenter's parallel loops: cv::parallel_for_ (OpenCV's pool, oneTBB here), with one seam
// for ThreadSanitizer builds. OpenCV's built-in TBB backend waits for a loop inside
// libopencv_core, which is not instrumented, so TSan saw no order between a body run on a worker
// and the code after the loop and reported races that are not there. TSan builds hand OpenCV the
// TBB backend of OpenCV's own header instead, compiled in parallel.cpp (instrumented, on the
// instrumented oneTBB of scripts/build-tsan-tbb), before main and again before our first loop.
// Other builds keep OpenCV's built-in backend: the same oneTBB.
#include <opencv2/core.hpp>
#include <utility>

namespace sonoshape::segmentation::detail {

/// TSan builds: sets OpenCV's parallel backend to the instrumented one, once. Otherwise nothing.
void use_instrumented_parallel_backend();

template <typename Body>
void parallel_for(const cv::Range& range, Body&& body) {
#if defined(__SANITIZE_THREAD__)
  use_instrumented_parallel_backend();
#endif
  cv::parallel_for_(range, std::forward<Body>(body));
}

}  // namespace sonoshape::segmentation::detail
