#pragma once
// A stable counting sort of items 0 .. n-1 by bucket, in parallel over fixed chunks of the items:
// per chunk a count per bucket, a prefix sum in (bucket, chunk) order, then each chunk places its
// items in increasing index. Every bucket lists its items in increasing index -- the order a serial
// counting sort gives -- whatever the chunk or thread count, so the sums taken over a bucket later
// do not depend on the thread count (docs/design.md §5.3). O(n + chunks * buckets) work.
// Used to bin particles by layout block (sim/particles/particles.h) and by raster leaf
// (sim/geometry/sphere_raster.cpp).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "parallel/fork_policy.h"

namespace stokes::sparse_grid {

/// [begin, end) of chunk `ch` of `chunks` equal parts of n items.
inline std::pair<std::size_t, std::size_t> chunkRange(std::size_t n, std::size_t chunks, std::size_t ch) {
  return {n * ch / chunks, n * (ch + 1) / chunks};
}

/// The items bucket by bucket: those of bucket k are items[start[k] .. start[k + 1]).
template <class Index>
struct BucketOrder {
  std::vector<Index> start;  ///< buckets + 1 offsets
  std::vector<Index> items;
};

/// Sorts the items 0 .. n-1 by bucketOf(i) (in [0, buckets), or negative to leave item i out),
/// stably, over `chunks` fixed chunks (at least 1). Index must hold n.
template <class Index, class BucketOf>
BucketOrder<Index> sortByBucket(std::size_t n, std::size_t buckets, std::size_t chunks, const BucketOf& bucketOf) {
  chunks = std::max<std::size_t>(chunks, 1);
  std::vector<Index> place(chunks * buckets, 0);  // per (chunk, bucket): a count, then a first place
#pragma omp parallel if (chunks > 1)
  {
    parallel::countTeam(parallel::Region::ParticleSort);
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t ch = 0; ch < std::ptrdiff_t(chunks); ++ch) {
      const auto [b, e] = chunkRange(n, chunks, std::size_t(ch));
      Index* count = place.data() + std::size_t(ch) * buckets;
      for (std::size_t i = b; i < e; ++i) {
        const auto k = bucketOf(i);
        if (k >= 0) ++count[std::size_t(k)];
      }
    }
  }
  BucketOrder<Index> out;
  out.start.assign(buckets + 1, 0);
  Index next = 0;
  for (std::size_t k = 0; k < buckets; ++k) {
    out.start[k] = next;
    for (std::size_t ch = 0; ch < chunks; ++ch) {
      const Index count = place[ch * buckets + k];
      place[ch * buckets + k] = next;
      next += count;
    }
  }
  out.start[buckets] = next;
  out.items.resize(std::size_t(next));
#pragma omp parallel for schedule(static) if (chunks > 1)
  for (std::ptrdiff_t ch = 0; ch < std::ptrdiff_t(chunks); ++ch) {
    const auto [b, e] = chunkRange(n, chunks, std::size_t(ch));
    Index* at = place.data() + std::size_t(ch) * buckets;
    for (std::size_t i = b; i < e; ++i) {
      const auto k = bucketOf(i);
      if (k >= 0) out.items[std::size_t(at[std::size_t(k)]++)] = Index(i);
    }
  }
  return out;
}

}  // namespace stokes::sparse_grid
