#pragma once
// Giving freed memory back to the system.
#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace sonoshape {

/// Returns the allocator's free pages to the system (glibc's malloc_trim; nothing elsewhere).
/// glibc keeps freed pages mapped, so a process's resident memory follows its largest
/// allocation burst rather than what it holds; the call costs one walk of the free lists.
inline void release_free_heap() {
#ifdef __GLIBC__
  malloc_trim(0);
#endif
}

}  // namespace sonoshape
