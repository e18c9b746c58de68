// Sparse voxel storage for TSDF fusion: 8×8×8-voxel blocks, allocated on
// demand and found through a flat open-addressing hash of block coordinates.
//
// The map knows nothing about cameras or frames: it is a container that a
// fusion step fills, a mesher reads, and (later) a temporal step may keep
// across frames and warp. Blocks are addressed by a dense index in
// [0, size()), stable until Clear().
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace holo {

inline constexpr int kBlockSide = 8;
inline constexpr int kBlockVoxels = kBlockSide * kBlockSide * kBlockSide;

// Integer coordinates of a block: voxel (i, j, k) of block (bx, by, bz) has
// the global voxel index (8·bx + i, 8·by + j, 8·bz + k), and its centre sits
// at that index times the voxel size (world metres).
struct BlockCoord {
  int32_t x = 0, y = 0, z = 0;
  bool operator==(const BlockCoord& o) const { return x == o.x && y == o.y && z == o.z; }
};

// Block coordinates must lie in [-kMaxBlockCoord, kMaxBlockCoord) on every
// axis (21 bits each, packed into one 64-bit key): at 5 mm voxels ±41 km.
inline constexpr int32_t kMaxBlockCoord = 1 << 20;

inline bool BlockCoordInRange(int64_t x, int64_t y, int64_t z) {
  return x >= -kMaxBlockCoord && x < kMaxBlockCoord && y >= -kMaxBlockCoord && y < kMaxBlockCoord &&
         z >= -kMaxBlockCoord && z < kMaxBlockCoord;
}

// Voxel data of one block, structure of arrays; voxel (i, j, k) is at
// index i + 8·j + 64·k.
struct alignas(64) VoxelBlock {
  // Signed distance to the surface divided by the truncation distance, in
  // [-1, 1]: positive in front of the surface (free space), negative behind.
  float tsdf[kBlockVoxels];
  // Sum of the observation weights; 0 = never observed (tsdf meaningless).
  float weight[kBlockVoxels];
  // Weighted mean colour, RGB8.
  uint8_t r[kBlockVoxels];
  uint8_t g[kBlockVoxels];
  uint8_t b[kBlockVoxels];

  void Clear();
};

// Summary flags of a block, refreshed by whoever writes its voxels; the
// mesher uses them to skip blocks that cannot contain a surface.
enum BlockFlags : uint8_t {
  kBlockHasNegative = 1,  // some observed voxel has tsdf < 0
  kBlockHasPositive = 2,  // some observed voxel has tsdf ≥ 0
  kBlockHasPositiveInBand = 4,  // some observed voxel has 0 ≤ tsdf < 0.999 (not beyond the band in every view)
};

inline uint8_t BlockFlagsOf(bool has_negative, bool has_positive, bool has_positive_in_band) {
  return static_cast<uint8_t>((has_negative ? kBlockHasNegative : 0) | (has_positive ? kBlockHasPositive : 0) |
                              (has_positive_in_band ? kBlockHasPositiveInBand : 0));
}

class VoxelBlockMap {
 public:
  static constexpr int32_t kNotFound = -1;

  VoxelBlockMap();

  // Index of the block at `c`, or kNotFound.
  int32_t Find(const BlockCoord& c) const {
    if (num_blocks_ == 0) return kNotFound;
    const uint64_t key = Pack(c);
    for (size_t s = Slot(key);; s = (s + 1) & slot_mask_) {
      if (slot_keys_[s] == key) return slot_values_[s];
      if (slot_keys_[s] == kEmpty) return kNotFound;
    }
  }

  // Index of the block at `c`, allocating it with cleared voxels (weight 0)
  // if absent; `*created` (if not null) says which. `c` must be in range
  // (BlockCoordInRange; checked). With `clear` false a new block's voxels are
  // left as they are (stale memory): the caller must write every voxel
  // before anyone reads the block.
  int32_t FindOrAllocate(const BlockCoord& c, bool* created = nullptr, bool clear = true);

  // Number of blocks in use.
  size_t size() const { return num_blocks_; }
  const BlockCoord& coord(int32_t index) const { return coords_[static_cast<size_t>(index)]; }
  VoxelBlock& block(int32_t index) { return blocks_[static_cast<size_t>(index)]; }
  const VoxelBlock& block(int32_t index) const { return blocks_[static_cast<size_t>(index)]; }
  uint8_t flags(int32_t index) const { return flags_[static_cast<size_t>(index)]; }
  void set_flags(int32_t index, uint8_t f) { flags_[static_cast<size_t>(index)] = f; }

  // Removes every block but keeps the memory, so refilling the map to a
  // similar size allocates nothing.
  void Clear();

  // Bytes reserved by the map (blocks, coordinates, hash slots).
  size_t MemoryBytes() const;

 private:
  static constexpr uint64_t kEmpty = ~uint64_t{0};
  static uint64_t Pack(const BlockCoord& c) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(c.x + kMaxBlockCoord)) << 42) |
           (static_cast<uint64_t>(static_cast<uint32_t>(c.y + kMaxBlockCoord)) << 21) |
           static_cast<uint64_t>(static_cast<uint32_t>(c.z + kMaxBlockCoord));
  }
  size_t Slot(uint64_t key) const {
    // Fibonacci hashing: the high bits of key·2^64/φ are well mixed.
    return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> hash_shift_);
  }
  void Rehash(size_t num_slots);

  std::vector<uint64_t> slot_keys_;
  std::vector<int32_t> slot_values_;
  size_t slot_mask_ = 0;
  int hash_shift_ = 64;
  std::vector<VoxelBlock> blocks_;  // blocks_.size() ≥ num_blocks_; the rest is kept for reuse
  std::vector<BlockCoord> coords_;
  std::vector<uint8_t> flags_;
  size_t num_blocks_ = 0;
};

}  // namespace holo
