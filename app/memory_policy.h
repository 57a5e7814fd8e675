#pragma once
// Heap policy of the stokesvdb program: keep freed memory for the next step instead of handing it
// back to the kernel.
//
// Every grid step builds its systems, Krylov vectors and multigrid levels afresh (megabytes to
// gigabytes of zero-filled arrays). glibc serves blocks above its mmap threshold with fresh
// mmap() pages and returns them on free, and trims the heap top, so each step pays a page fault
// for every 4 KiB it touches; on the development VM a fault is expensive (paravirtualised).
// Measured (armadillos res 96, 2 frames, 1 thread, two runs each): 112,560-120,067 minor
// faults, Stokes stage 1.72-1.73 s, run 6.1-6.2 s; with freed memory kept, 24,839-24,924 faults,
// 0.60-0.61 s, 4.7-5.1 s, and the same peak resident memory (137 MB).

namespace stokes::app {

/// Serves every allocation from the heap (no per-block mmap) and never trims it, unless the user
/// set glibc's own malloc tunables (GLIBC_TUNABLES or MALLOC_*_ variables), which then win.
void keepFreedMemory();

}  // namespace stokes::app
