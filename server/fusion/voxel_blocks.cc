#include "server/fusion/voxel_blocks.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "common/status.h"

namespace holo {

void VoxelBlock::Clear() {
  std::memset(tsdf, 0, sizeof(tsdf));
  std::memset(weight, 0, sizeof(weight));
  std::memset(r, 0, sizeof(r));
  std::memset(g, 0, sizeof(g));
  std::memset(b, 0, sizeof(b));
}

VoxelBlockMap::VoxelBlockMap() { Rehash(1024); }

void VoxelBlockMap::Rehash(size_t num_slots) {
  HOLO_CHECK(std::has_single_bit(num_slots));
  slot_keys_.assign(num_slots, kEmpty);
  slot_values_.assign(num_slots, kNotFound);
  slot_mask_ = num_slots - 1;
  hash_shift_ = 64 - std::countr_zero(num_slots);
  for (size_t i = 0; i < num_blocks_; ++i) {
    const uint64_t key = Pack(coords_[i]);
    size_t s = Slot(key);
    while (slot_keys_[s] != kEmpty) s = (s + 1) & slot_mask_;
    slot_keys_[s] = key;
    slot_values_[s] = static_cast<int32_t>(i);
  }
}

int32_t VoxelBlockMap::FindOrAllocate(const BlockCoord& c, bool* created, bool clear) {
  HOLO_CHECK(BlockCoordInRange(c.x, c.y, c.z));
  const uint64_t key = Pack(c);
  size_t s = Slot(key);
  for (;; s = (s + 1) & slot_mask_) {
    if (slot_keys_[s] == key) {
      if (created) *created = false;
      return slot_values_[s];
    }
    if (slot_keys_[s] == kEmpty) break;
  }
  HOLO_CHECK_MSG(num_blocks_ < static_cast<size_t>(INT32_MAX), "too many voxel blocks");
  const int32_t index = static_cast<int32_t>(num_blocks_);
  if (num_blocks_ == blocks_.size()) {
    blocks_.emplace_back();
    coords_.emplace_back();
    flags_.emplace_back();
  }
  if (clear) blocks_[num_blocks_].Clear();
  coords_[num_blocks_] = c;
  flags_[num_blocks_] = 0;
  ++num_blocks_;
  // Keep the load factor ≤ 1/2 so probe sequences stay short.
  if (2 * num_blocks_ > slot_keys_.size()) {
    Rehash(2 * slot_keys_.size());
  } else {
    slot_keys_[s] = key;
    slot_values_[s] = index;
  }
  if (created) *created = true;
  return index;
}

void VoxelBlockMap::Clear() {
  if (num_blocks_ == 0) return;
  // Clearing only the used slots costs O(blocks), not O(capacity).
  for (size_t i = 0; i < num_blocks_; ++i) {
    const uint64_t key = Pack(coords_[i]);
    size_t s = Slot(key);
    while (slot_keys_[s] != key) s = (s + 1) & slot_mask_;
    slot_keys_[s] = kEmpty;
    slot_values_[s] = kNotFound;
  }
  num_blocks_ = 0;
}

size_t VoxelBlockMap::MemoryBytes() const {
  return blocks_.capacity() * sizeof(VoxelBlock) + coords_.capacity() * sizeof(BlockCoord) + flags_.capacity() +
         slot_keys_.capacity() * (sizeof(uint64_t) + sizeof(int32_t));
}

}  // namespace holo
