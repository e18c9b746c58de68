// Small procedural meshes and images for the protocol tests.
#pragma once

#include <cmath>
#include <cstdint>
#include <algorithm>
#include <random>

#include "common/image.h"
#include "common/mesh.h"

namespace holo::test {

// A closed, noisy latitude–longitude sphere (radius `r` metres around `c`),
// rows × cols quads plus pole fans, with normals and smooth noisy colours.
inline Mesh NoisySphere(int rows, int cols, float r = 0.3f, Eigen::Vector3f c = {0.2f, -0.1f, 1.1f},
                        uint32_t seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.002f);
  std::uniform_int_distribution<int> cn(-6, 6);
  Mesh m;
  auto add = [&](float theta, float phi) {
    const Eigen::Vector3f d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
    const float rr = r * (1.0f + 0.05f * std::sin(5 * phi) * std::sin(3 * theta)) + noise(rng);
    m.positions.push_back(c + rr * d);
    const int g = static_cast<int>(127 + 100 * d.z());
    m.colors.push_back({static_cast<uint8_t>(std::clamp(g + cn(rng), 0, 255)),
                        static_cast<uint8_t>(std::clamp(90 + cn(rng), 0, 255)),
                        static_cast<uint8_t>(std::clamp(255 - g + cn(rng), 0, 255))});
  };
  add(0, 0);  // north pole
  for (int i = 1; i <= rows; ++i)
    for (int j = 0; j < cols; ++j) add(static_cast<float>(M_PI) * i / (rows + 1), 2 * static_cast<float>(M_PI) * j / cols);
  add(static_cast<float>(M_PI), 0);  // south pole
  const auto at = [&](int i, int j) { return static_cast<uint32_t>(1 + (i - 1) * cols + (j % cols)); };
  const uint32_t south = static_cast<uint32_t>(m.positions.size() - 1);
  for (int j = 0; j < cols; ++j) m.triangles.push_back({0, at(1, j), at(1, j + 1)});
  for (int i = 1; i < rows; ++i)
    for (int j = 0; j < cols; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  for (int j = 0; j < cols; ++j) m.triangles.push_back({at(rows, j), south, at(rows, j + 1)});
  // Area-weighted vertex normals (computed here: Mesh::ComputeNormals does not link, see the protocol issue note).
  m.normals.assign(m.positions.size(), Eigen::Vector3f::Zero());
  for (const auto& t : m.triangles) {
    const Eigen::Vector3f e1 = m.positions[t[1]] - m.positions[t[0]], e2 = m.positions[t[2]] - m.positions[t[0]];
    const Eigen::Vector3f fn(e1.y() * e2.z() - e1.z() * e2.y(), e1.z() * e2.x() - e1.x() * e2.z(),
                             e1.x() * e2.y() - e1.y() * e2.x());
    for (uint32_t v : t) m.normals[v] += fn;
  }
  for (auto& n : m.normals) n = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : Eigen::Vector3f::UnitZ();
  return m;
}

// A textured image with an elliptic foreground mask.
inline void MaskedImage(int w, int h, ImageRgb8* image, ImageGray8* mask, uint32_t seed = 1) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> n(-4, 4);
  image->Resize(w, h);
  mask->Resize(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float dx = (x - 0.45f * w) / (0.2f * w), dy = (y - 0.55f * h) / (0.35f * h);
      mask->at(x, y) = dx * dx + dy * dy < 1 ? 255 : 0;
      image->at(x, y, 0) = static_cast<uint8_t>(std::clamp(120 + 60 * std::sin(x * 0.05f) + n(rng), 0.0f, 255.0f));
      image->at(x, y, 1) = static_cast<uint8_t>(std::clamp(100 + 50 * std::cos(y * 0.07f) + n(rng), 0.0f, 255.0f));
      image->at(x, y, 2) = static_cast<uint8_t>(std::clamp(80 + 0.2f * x + n(rng), 0.0f, 255.0f));
    }
}

}  // namespace holo::test
