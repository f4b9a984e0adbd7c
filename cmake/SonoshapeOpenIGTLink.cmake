# OpenIGTLink (Debian libopenigtlink-dev 1.11, protocol v2) as the imported target
# sonoshape::openigtlink, behind SONOSHAPE_WITH_OPENIGTLINK: on by default where the library is
# installed, so that a machine without it still builds everything else.
# The package's config file sets variables only (no imported target, and compile flags meant for
# building the library itself), so the target is assembled here from its include and library
# directories.
find_package(OpenIGTLink QUIET HINTS /usr/lib/openigtlink)
if(OpenIGTLink_FOUND)
  find_library(SONOSHAPE_OPENIGTLINK_LIBRARY NAMES OpenIGTLink HINTS ${OpenIGTLink_LIBRARY_DIRS})
endif()
if(OpenIGTLink_FOUND AND SONOSHAPE_OPENIGTLINK_LIBRARY)
  set(_sonoshape_igtl_default ON)
else()
  set(_sonoshape_igtl_default OFF)
endif()
option(SONOSHAPE_WITH_OPENIGTLINK
       "OpenIGTLink: `scan --igtl-serve` (needs libopenigtlink-dev)" ${_sonoshape_igtl_default})

if(SONOSHAPE_WITH_OPENIGTLINK)
  if(NOT OpenIGTLink_FOUND OR NOT SONOSHAPE_OPENIGTLINK_LIBRARY)
    message(FATAL_ERROR "SONOSHAPE_WITH_OPENIGTLINK is ON but OpenIGTLink was not found: run "
                        "scripts/install-deps (Debian: libopenigtlink-dev), or configure with "
                        "-DSONOSHAPE_WITH_OPENIGTLINK=OFF")
  endif()
  add_library(sonoshape_openigtlink INTERFACE)
  add_library(sonoshape::openigtlink ALIAS sonoshape_openigtlink)
  # SYSTEM: the library's headers are not warning-clean under -Wpedantic.
  target_include_directories(sonoshape_openigtlink SYSTEM INTERFACE ${OpenIGTLink_INCLUDE_DIRS})
  target_link_libraries(sonoshape_openigtlink INTERFACE ${SONOSHAPE_OPENIGTLINK_LIBRARY}
                                                        Threads::Threads)
  message(STATUS "OpenIGTLink ${OpenIGTLink_VERSION_MAJOR}.${OpenIGTLink_VERSION_MINOR} "
                 "(protocol ${OpenIGTLink_PROTOCOL_VERSION}): ${SONOSHAPE_OPENIGTLINK_LIBRARY}")
endif()
