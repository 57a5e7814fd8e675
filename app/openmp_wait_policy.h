#pragma once
// OpenMP wait policy of the stokesvdb program.
//
// libgomp's default (OMP_WAIT_POLICY unset) spins ~300,000 times at every barrier before it
// sleeps. Two such programs sharing the cores spin against each other's descheduled threads:
// measured on the 2-core VM (disk N = 128, Jacobi CG, 2 threads, beside a second 2-thread solve),
// 6-65 ms per iteration against 1.1 ms alone; with the passive policy 2.0 ms, i.e. one core's
// worth, as it should be (bench/results/threads.md). libgomp reads the policy from the environment
// when it is loaded, before main, so the program sets it and re-executes itself once.

namespace stokes::app {

/// When neither OMP_WAIT_POLICY nor GOMP_SPINCOUNT is set, sets OMP_WAIT_POLICY=passive and
/// re-executes the program (/proc/self/exe) with the same arguments; returns only when the policy
/// was already chosen by the user or the re-execution is not possible (then libgomp's default
/// stays). OMP_WAIT_POLICY=active gives the spinning default back.
void choosePassiveWaitPolicy(char** argv);

/// The wait policy in force: the environment's OMP_WAIT_POLICY, or "default".
const char* waitPolicy();

}  // namespace stokes::app
