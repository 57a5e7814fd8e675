#pragma once
// The global numbering of a system's live rows split over MPI ranks by blocks (docs/petsc.md,
// "Partition"), for any system whose rows are samples of a block layout: each live row has a key
// channel * numSlots + slot (a pressure, a stress channel, a face axis, a rigid multiplier...),
// and every block of the layout an owner rank, which owns the live rows of all channels there.
//
// The numbering is rank-major, and within a rank block-major in the rank's block order, each
// block's rows channel by channel in slot order: a row's number is its block's first number plus
// its place among the block's live rows. So the owner of a block can describe all of its numbers
// with that first number and a bitmap of live rows per channel. A rank that reads rows of blocks
// it does not own (its ghosts) asks their owners for exactly that (askRanks), and checks that the
// owners' live rows are the ones it sees: a halo whose weights differ from the owner's would
// silently change the operator.
//
// Nothing here knows a system: the caller says which rows are live and which samples its
// stencils read.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "solver/petsc/petsc_krylov.h"
#include "sparse_grid/block_layout.h"

namespace stokes::solver::petsc {

/// The set bits of `words` (a bitmap, 64 bits a word) before bit `bit`: the place of that bit's
/// sample among a block's live ones, which numbers it from the block's first number.
inline std::int64_t setBitsBefore(const std::uint64_t* words, std::size_t bit) {
  std::int64_t count = std::popcount(words[bit / 64] & ((std::uint64_t(1) << (bit % 64)) - 1));
  for (std::size_t w = 0; w < bit / 64; ++w) count += std::popcount(words[w]);
  return count;
}

template <int Dim>
class BlockRows {
 public:
  static constexpr std::size_t kSlots = sparse_grid::BlockLayout<Dim>::kSlots;
  static constexpr std::size_t kBitmapWords = (kSlots + 63) / 64;

  /// keys[k]: channel * numSlots + slot of live row k, increasing, below channels * numSlots;
  /// owner: the rank of each of the layout's blocks. Collective (the ranks' row counts).
  BlockRows(const sparse_grid::BlockLayout<Dim>& layout, std::vector<std::int32_t> owner, int rank, int channels,
            std::vector<std::uint64_t> keys)
      : L_(&layout), n_(layout.numSlots()), rank_(rank), channels_(channels), owner_(std::move(owner)),
        keys_(std::move(keys)) {
    if (owner_.size() != L_->numBlocks()) throw std::invalid_argument("BlockRows: one owner per block");
    liveOfKey_.assign(std::size_t(channels_) * n_, -1);
    for (std::size_t k = 0; k < keys_.size(); ++k) {
      if (keys_[k] >= liveOfKey_.size() || (k > 0 && keys_[k] <= keys_[k - 1]))
        throw std::invalid_argument("BlockRows: keys must be increasing and below channels x slots");
      liveOfKey_[keys_[k]] = std::int32_t(k);
    }
    numberOwned();
  }

  std::size_t blockOfKey(std::uint64_t key) const { return std::size_t(key % n_) / kSlots; }
  bool ownsBlock(std::size_t b) const { return owner_[b] == rank_; }
  const std::vector<std::int32_t>& owners() const { return owner_; }
  /// Live row of a key, or -1.
  std::int32_t liveOfKey(std::uint64_t key) const { return liveOfKey_[key]; }
  std::uint64_t key(std::size_t live) const { return keys_[live]; }

  std::int64_t firstRow() const { return firstRow_; }
  std::int64_t globalRows() const { return globalRows_; }
  /// The live rows this rank owns, in the numbering's order (firstRow(), firstRow() + 1, ...).
  const std::vector<std::uint32_t>& owned() const { return owned_; }
  /// After numberGhosts: the live rows the rank reads (its own and its ghosts), by number.
  const std::vector<std::uint32_t>& read() const { return read_; }
  /// The number of a live row the rank owns or reads, else -1.
  std::int64_t globalOf(std::size_t live) const { return globalOfLive_[live]; }

  /// Numbers the ghosts. `readKeys`: every sample the rank's stencils and results read (live here
  /// or not, its own included). Collective.
  void numberGhosts(const std::vector<std::uint64_t>& readKeys) {
    const int ranks = petsc::ranks();
    std::vector<std::vector<std::int32_t>> asks(ranks);
    std::vector<std::vector<std::int32_t>> askedBlocks(ranks);
    std::vector<std::uint8_t> asked(L_->numBlocks(), 0);
    for (std::uint64_t key : readKeys) {
      const std::size_t b = blockOfKey(key);
      if (ownsBlock(b) || asked[b]) continue;
      asked[b] = 1;
      const int r = owner_[b];
      if (r < 0 || r >= ranks) throw std::invalid_argument("BlockRows: a block's owner is not a rank");
      for (int a = 0; a < 3; ++a) asks[r].push_back(L_->blockOrigin(b)[a]);
      askedBlocks[r].push_back(std::int32_t(b));
    }
    const int words = 1 + channels_ * int(kBitmapWords);
    const std::vector<std::vector<std::uint64_t>> replies =
        askRanks(asks, 3, words, [&](const std::int32_t* origin, std::uint64_t* record) {
          const std::int32_t b = L_->blockAt(sparse_grid::Coord(origin[0], origin[1], origin[2]));
          if (b < 0 || !ownsBlock(std::size_t(b)))
            throw std::logic_error("BlockRows: asked for the rows of a block this rank does not own");
          record[0] = std::uint64_t(blockStart_[std::size_t(b)]);
          liveBitmap(std::size_t(b), record + 1);
        });
    std::vector<const std::uint64_t*> recordOfBlock(L_->numBlocks(), nullptr);
    for (int r = 0; r < ranks; ++r)
      for (std::size_t i = 0; i < askedBlocks[r].size(); ++i)
        recordOfBlock[std::size_t(askedBlocks[r][i])] = replies[r].data() + i * std::size_t(words);
    std::vector<std::uint8_t> reads(keys_.size(), 0);
    for (std::uint32_t k : owned_) reads[k] = 1;
    for (std::uint64_t key : readKeys) {
      const std::size_t b = blockOfKey(key);
      const std::int32_t live = liveOfKey_[key];
      if (ownsBlock(b)) {
        if (live >= 0) reads[std::size_t(live)] = 1;
        continue;
      }
      std::int64_t number = -1;
      if (ownersBit(recordOfBlock[b], key, &number) != (live >= 0))
        throw std::logic_error("BlockRows: a halo sample that this rank's stencils read is " +
                               std::string(live >= 0 ? "live here but not" : "not live here but") +
                               " on its owner (the halo's weights differ from the owner's)");
      if (live < 0) continue;
      reads[std::size_t(live)] = 1;
      globalOfLive_[std::size_t(live)] = number;
    }
    read_.clear();
    for (std::size_t k = 0; k < keys_.size(); ++k)
      if (reads[k]) read_.push_back(std::uint32_t(k));
    std::sort(read_.begin(), read_.end(),
              [&](std::uint32_t x, std::uint32_t y) { return globalOfLive_[x] < globalOfLive_[y]; });
  }

  /// padded[paddedOfLive[k]] = values of the rows the rank reads (read()'s order): its own and its
  /// ghosts' solution, which give A x on its rows and the results of its blocks.
  template <class Index>
  void scatterRead(const std::vector<double>& values, const std::vector<Index>& paddedOfLive, double* padded) const {
    if (values.size() != read_.size()) throw std::logic_error("BlockRows::scatterRead: one value per row read");
    for (std::size_t g = 0; g < read_.size(); ++g) padded[paddedOfLive[read_[g]]] = values[g];
  }
  /// The same for the global solution (rank-major, allGather's order) of a whole problem held by
  /// every rank.
  template <class Index>
  void scatterWhole(const std::vector<double>& global, const std::vector<Index>& paddedOfLive, double* padded) const {
    const std::vector<std::uint32_t> order = wholeOrder();
    if (order.size() != global.size()) throw std::logic_error("BlockRows::scatterWhole: not the whole problem");
    for (std::size_t k = 0; k < order.size(); ++k) padded[paddedOfLive[order[k]]] = global[k];
  }

 private:
  // Every live row in the numbering's order. Only for a whole problem held by every rank: each
  // numbers every block by the owners' rule.
  std::vector<std::uint32_t> wholeOrder() const {
    std::vector<std::vector<std::uint32_t>> rowsOfBlock(L_->numBlocks());
    for (std::size_t k = 0; k < keys_.size(); ++k) rowsOfBlock[blockOfKey(keys_[k])].push_back(std::uint32_t(k));
    std::vector<std::uint32_t> order;
    const int ranks = 1 + *std::max_element(owner_.begin(), owner_.end());
    for (int r = 0; r < ranks; ++r)
      for (std::size_t b = 0; b < rowsOfBlock.size(); ++b)
        if (owner_[b] == r) order.insert(order.end(), rowsOfBlock[b].begin(), rowsOfBlock[b].end());
    return order;
  }

  // The rank's rows, block-major; their numbers start after the earlier ranks' rows.
  void numberOwned() {
    std::vector<std::vector<std::uint32_t>> rowsOfBlock(L_->numBlocks());
    std::size_t count = 0;
    for (std::size_t k = 0; k < keys_.size(); ++k)
      if (ownsBlock(blockOfKey(keys_[k]))) rowsOfBlock[blockOfKey(keys_[k])].push_back(std::uint32_t(k)), ++count;
    firstRow_ = std::int64_t(sumOverEarlierRanks(count));
    globalRows_ = std::int64_t(std::llround(sumOverRanks(double(count))));
    globalOfLive_.assign(keys_.size(), -1);
    blockStart_.assign(L_->numBlocks(), -1);
    for (std::size_t b = 0; b < L_->numBlocks(); ++b) {
      if (!ownsBlock(b)) continue;
      blockStart_[b] = firstRow_ + std::int64_t(owned_.size());
      for (std::uint32_t k : rowsOfBlock[b]) {
        globalOfLive_[k] = firstRow_ + std::int64_t(owned_.size());
        owned_.push_back(k);
      }
    }
  }

  // Bit (channel c, slot s) of block b: whether that sample is a live row.
  void liveBitmap(std::size_t b, std::uint64_t* words) const {
    std::fill(words, words + std::size_t(channels_) * kBitmapWords, std::uint64_t(0));
    for (int c = 0; c < channels_; ++c)
      for (std::size_t s = 0; s < kSlots; ++s)
        if (liveOfKey_[std::size_t(c) * n_ + b * kSlots + s] >= 0)
          words[std::size_t(c) * kBitmapWords + s / 64] |= std::uint64_t(1) << (s % 64);
  }

  // The owner's bit of a key in its block's record; its number (the block's first plus the live
  // rows before it) if live.
  bool ownersBit(const std::uint64_t* record, std::uint64_t key, std::int64_t* number) const {
    const std::size_t c = key / n_, s = key % n_ - blockOfKey(key) * kSlots;
    const std::uint64_t* bits = record + 1;
    const std::size_t bit = c * kBitmapWords * 64 + s;
    *number = std::int64_t(record[0]) + setBitsBefore(bits, bit);
    return (bits[bit / 64] >> (bit % 64) & 1) != 0;
  }

  const sparse_grid::BlockLayout<Dim>* L_;
  std::size_t n_;
  int rank_, channels_;
  std::vector<std::int32_t> owner_;
  std::vector<std::uint64_t> keys_;
  std::vector<std::int32_t> liveOfKey_;
  std::int64_t firstRow_ = 0, globalRows_ = 0;
  std::vector<std::int64_t> blockStart_, globalOfLive_;
  std::vector<std::uint32_t> owned_, read_;
};

}  // namespace stokes::solver::petsc
