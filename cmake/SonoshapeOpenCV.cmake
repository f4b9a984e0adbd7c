# OpenCV core and imgproc as the imported target sonoshape::opencv. Not imgcodecs: on Debian it
# links GDAL and about 120 other libraries, which every program would load at its start (0.17 s
# each) and every machine would install; libpng (core/png_file.hpp) and libjpeg-turbo (the V4L2
# grabber's MJPG frames) do its two jobs here.
# Debian ships OpenCVConfig.cmake only in the libopencv-dev metapackage (which pulls in every
# module, VTK and Qt); the per-module -dev packages are enough, so fall back to finding their
# headers and libraries directly.
find_package(OpenCV 4 QUIET COMPONENTS core imgproc)
add_library(sonoshape_opencv INTERFACE)
add_library(sonoshape::opencv ALIAS sonoshape_opencv)
if(OpenCV_FOUND)
  target_include_directories(sonoshape_opencv SYSTEM INTERFACE ${OpenCV_INCLUDE_DIRS})
  target_link_libraries(sonoshape_opencv INTERFACE opencv_core opencv_imgproc)
else()
  find_path(SONOSHAPE_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4)
  # opencv2/opencv_modules.hpp lives in the multiarch include directory on Debian.
  find_path(SONOSHAPE_OPENCV_MODULES_DIR opencv2/opencv_modules.hpp
            PATH_SUFFIXES opencv4 ${CMAKE_LIBRARY_ARCHITECTURE}/opencv4)
  set(_sonoshape_opencv_libs)
  foreach(module core imgproc)
    find_library(SONOSHAPE_OPENCV_${module}_LIBRARY opencv_${module})
    list(APPEND _sonoshape_opencv_libs ${SONOSHAPE_OPENCV_${module}_LIBRARY})
    if(NOT SONOSHAPE_OPENCV_${module}_LIBRARY)
      set(_sonoshape_opencv_missing TRUE)
    endif()
  endforeach()
  if(NOT SONOSHAPE_OPENCV_INCLUDE_DIR OR NOT SONOSHAPE_OPENCV_MODULES_DIR
     OR _sonoshape_opencv_missing)
    message(FATAL_ERROR "OpenCV (core, imgproc) not found: run scripts/install-deps "
                        "(Debian: libopencv-core-dev libopencv-imgproc-dev)")
  endif()
  target_include_directories(sonoshape_opencv SYSTEM INTERFACE ${SONOSHAPE_OPENCV_INCLUDE_DIR}
                                                               ${SONOSHAPE_OPENCV_MODULES_DIR})
  target_link_libraries(sonoshape_opencv INTERFACE ${_sonoshape_opencv_libs})
  message(STATUS "OpenCV: ${SONOSHAPE_OPENCV_INCLUDE_DIR} (per-module Debian packages)")
endif()
