#include "app/memory_policy.h"

#include <malloc.h>

#include <cstdlib>
#include <cstring>

extern char** environ;

namespace stokes::app {

namespace {
bool userTunedMalloc() {
  if (std::getenv("GLIBC_TUNABLES")) return true;
  for (char** e = environ; e && *e; ++e)
    if (std::strncmp(*e, "MALLOC_", 7) == 0) return true;
  return false;
}
}  // namespace

void keepFreedMemory() {
  if (userTunedMalloc()) return;
  mallopt(M_MMAP_MAX, 0);             // no mmap()-backed blocks: large arrays come from the heap
  mallopt(M_TRIM_THRESHOLD, -1);      // (size_t)-1: never give the heap top back
}

}  // namespace stokes::app
