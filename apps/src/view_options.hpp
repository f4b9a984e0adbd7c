#pragma once
// What `sonoshape view` and `scan --view` share.
namespace sonoshape::apps {

/// Where the page is served unless --http / --view says otherwise: loopback only.
inline constexpr const char* kDefaultViewAddress = "127.0.0.1:8080";

/// Why the browser view is not there, and how to get it.
inline constexpr const char* kViewerMissing =
    "this sonoshape was built without the browser view: install libboost-dev (Boost.Beast) and "
    "configure with -DSONOSHAPE_WITH_VIEWER=ON";

}  // namespace sonoshape::apps
