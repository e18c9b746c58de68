// Shared by the G2 tests (codec_geometry2_test: the decoder's refusals, run
// under the sanitizers too; geometry2_encoder_test: the encoder's behaviour,
// Release only, since the encoder is ~50x slower under ASan): a fused-like
// moving body re-extracted every frame, and coded sequences of it.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <unordered_map>

#include "common/metrics/mesh_shapes.h"
#include "common/metrics/triangle_index.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/geometry2_codec.h"

namespace holo::protocol::g2test {

// Marching tetrahedra of a torso (sphere) with an arm (capsule) swinging by
// `frame`, at `voxel` metres.
inline Mesh MovingBody(int frame, float voxel) {
  const Eigen::Vector3f torso(0.0f, 0.0f, 1.5f);
  const float angle = 0.06f * static_cast<float>(frame);
  const Eigen::Vector3f shoulder(0.1f, 0.0f, 1.55f);
  const Eigen::Vector3f hand = shoulder + 0.2f * Eigen::Vector3f(std::cos(angle), std::sin(angle), -0.3f).normalized();
  auto sdf = [&](const Eigen::Vector3f& p) {
    const float body = (p - torso).norm() - 0.13f;
    const Eigen::Vector3f ab = hand - shoulder;
    const float h = std::clamp((p - shoulder).dot(ab) / ab.squaredNorm(), 0.0f, 1.0f);
    const float arm = (p - shoulder - h * ab).norm() - 0.035f;
    // Per-frame ripple of ±0.3 mm: a re-fused surface is never quite the same.
    const float ripple = 0.0003f * std::sin(40 * p.x() + 1.7f * frame) * std::sin(37 * p.y() - 1.3f * frame);
    return std::min(body, arm) + ripple;
  };
  const Eigen::Vector3f lo(-0.17f, -0.17f, 1.33f);
  const int nx = static_cast<int>(0.52f / voxel) + 1, ny = static_cast<int>(0.42f / voxel) + 1,
            nz = static_cast<int>(0.34f / voxel) + 1;
  return metrics::MakeSdfMesh(sdf, lo, Eigen::Vector3i(nx, ny, nz), voxel,
                              [](const Eigen::Vector3f&, uint32_t idx) -> std::array<uint8_t, 3> {
                                return {static_cast<uint8_t>(100 + idx % 50), 120, 140};
                              });
}

// Two-sided RMS point-to-surface distance (vertices of each to the other's
// surface), metres: the bench's measure.
inline double TwoSidedRms(const Mesh& a, const Mesh& b) {
  auto ia = metrics::TriangleIndex::Build(a);
  auto ib = metrics::TriangleIndex::Build(b);
  EXPECT_TRUE(ia.ok() && ib.ok());
  double se = 0;
  for (const auto& p : a.positions) se += std::pow(std::min(ib->Query(p, 0.05f).distance, 0.05f), 2);
  for (const auto& p : b.positions) se += std::pow(std::min(ia->Query(p, 0.05f).distance, 0.05f), 2);
  return std::sqrt(se / static_cast<double>(a.num_vertices() + b.num_vertices()));
}

struct Coded {
  std::vector<std::vector<uint8_t>> blobs;
  std::vector<Geometry2FrameInfo> infos;
  std::vector<Mesh> inputs;
};

inline Coded EncodeSequence(int frames, float voxel, const Geometry2EncodeOptions& o = {}) {
  Coded c;
  Geometry2Encoder enc(o);
  for (int f = 0; f < frames; ++f) {
    c.inputs.push_back(MovingBody(f, voxel));
    c.blobs.emplace_back();
    c.infos.emplace_back();
    EXPECT_TRUE(enc.Encode(c.inputs.back(), &c.blobs.back(), &c.infos.back()).ok());
  }
  return c;
}

// One coded sequence shared by the encoder's tests (14 mm voxels; S8-QVGA
// fuses at 8).
inline const Coded& Sequence() {
  static const Coded c = EncodeSequence(8, 0.014f);
  return c;
}
// A small one (20 mm) for the decoder's tests: every prefix, bit flips, refusals.
inline const Coded& SmallSequence() {
  static const Coded c = EncodeSequence(3, 0.02f);
  return c;
}

inline bool SameMesh(const Mesh& a, const Mesh& b) {
  return a.positions == b.positions && a.normals == b.normals && a.colors == b.colors && a.triangles == b.triangles;
}

// Two bodies side by side: the second one appears or vanishes.
inline Mesh TwoBodies(int frame, float voxel) {
  Mesh two = MovingBody(frame, voxel);
  const Mesh other = MovingBody(frame, voxel);
  const auto base = static_cast<uint32_t>(two.positions.size());
  for (const auto& p : other.positions) two.positions.push_back(p + Eigen::Vector3f(0.6f, 0, 0));
  two.colors.insert(two.colors.end(), other.colors.begin(), other.colors.end());
  for (auto t : other.triangles) two.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  return two;
}

}  // namespace holo::protocol::g2test
