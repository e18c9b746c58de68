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
  auto id = [&](int i, int j, int k) { return (static_cast<size_t>(k) * ny + j) * nx + i; };
  auto pos = [&](int i, int j, int k) { return Eigen::Vector3f(lo + voxel * Eigen::Vector3f(i, j, k)); };
  std::vector<float> val(static_cast<size_t>(nx) * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) val[id(i, j, k)] = sdf(pos(i, j, k));
  Mesh m;
  std::unordered_map<uint64_t, uint32_t> edge_vertex;
  auto vertex = [&](size_t a, Eigen::Vector3f pa, size_t b, Eigen::Vector3f pb) {
    if (a > b) {
      std::swap(a, b);
      std::swap(pa, pb);
    }
    const uint64_t key = (static_cast<uint64_t>(a) << 32) | b;
    if (auto it = edge_vertex.find(key); it != edge_vertex.end()) return it->second;
    const float va = val[a], vb = val[b];
    const auto idx = static_cast<uint32_t>(m.positions.size());
    m.positions.push_back(pa + (va / (va - vb)) * (pb - pa));
    m.colors.push_back({static_cast<uint8_t>(100 + idx % 50), 120, 140});
    edge_vertex.emplace(key, idx);
    return idx;
  };
  static constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  static constexpr int kTets[6][4] = {{0, 5, 1, 6}, {0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6}, {0, 7, 4, 6}, {0, 4, 5, 6}};
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        size_t cid[8];
        Eigen::Vector3f cp[8];
        int inside = 0;
        for (int c = 0; c < 8; ++c) {
          cid[c] = id(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          cp[c] = pos(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          inside += val[cid[c]] < 0;
        }
        if (inside == 0 || inside == 8) continue;
        for (const auto& tet : kTets) {
          std::vector<int> in, out;
          for (int c : tet) (val[cid[c]] < 0 ? in : out).push_back(c);
          if (in.empty() || out.empty()) continue;
          Eigen::Vector3f gin = Eigen::Vector3f::Zero(), gout = Eigen::Vector3f::Zero();
          for (int c : in) gin += cp[c] / static_cast<float>(in.size());
          for (int c : out) gout += cp[c] / static_cast<float>(out.size());
          const Eigen::Vector3f outward = gout - gin;
          auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
            if (a == b || b == c || a == c) return;
            const Eigen::Vector3f n = (m.positions[b] - m.positions[a]).cross(m.positions[c] - m.positions[a]);
            if (n.dot(outward) < 0) std::swap(b, c);
            m.triangles.push_back({a, b, c});
          };
          auto v = [&](int a, int b) { return vertex(cid[a], cp[a], cid[b], cp[b]); };
          if (in.size() == 1 || in.size() == 3) {
            const int s = in.size() == 1 ? in[0] : out[0];
            const std::vector<int>& o = in.size() == 1 ? out : in;
            emit(v(s, o[0]), v(s, o[1]), v(s, o[2]));
          } else {
            const uint32_t a = v(in[0], out[0]), b = v(in[0], out[1]), c = v(in[1], out[1]), d = v(in[1], out[0]);
            emit(a, b, c);
            emit(a, c, d);
          }
        }
      }
  return m;
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
