#include "app/openmp_wait_policy.h"

#include <unistd.h>

#include <cstdlib>

namespace stokes::app {

void choosePassiveWaitPolicy(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr || std::getenv("GOMP_SPINCOUNT") != nullptr) return;
  if (setenv("OMP_WAIT_POLICY", "passive", 0) != 0) return;
  execv("/proc/self/exe", argv);
  // Reached only when exec failed (no /proc): keep running with libgomp's default; waitPolicy()
  // then reports "default" on the start line.
  unsetenv("OMP_WAIT_POLICY");
}

const char* waitPolicy() {
  const char* policy = std::getenv("OMP_WAIT_POLICY");
  return policy != nullptr ? policy : "default";
}

}  // namespace stokes::app
