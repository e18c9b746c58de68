// A synthetic rectified stereo pair for PatchMatch tests: a textured,
// slanted plane with exact left-view disparity d = a·x + b·y + c.
#pragma once

#include <cmath>
#include <cstdint>

#include "common/image.h"

namespace holo {

// A continuous random texture: bilinear interpolation of a hashed lattice
// with spacing 1.3 px, so it can be sampled at any sub-pixel position.
inline float SlantedPlaneTexture(float u, float v) {
  const float s = 1.0f / 1.3f;
  const float fu = u * s + 1000.0f, fv = v * s + 1000.0f;
  const int iu = static_cast<int>(fu), iv = static_cast<int>(fv);
  const float au = fu - iu, av = fv - iv;
  auto lattice = [](int x, int y) {
    uint64_t h = static_cast<uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^ static_cast<uint64_t>(y) * 0xC2B2AE3D27D4EB4FULL;
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ULL;
    h ^= h >> 32;
    return static_cast<float>(h & 0xff);
  };
  return (lattice(iu, iv) * (1 - au) + lattice(iu + 1, iv) * au) * (1 - av) +
         (lattice(iu, iv + 1) * (1 - au) + lattice(iu + 1, iv + 1) * au) * av;
}

struct SyntheticPair {
  ImageGray8 left, right;
  ImageFloat truth;  // left-view disparity
  SyntheticPair(int W, int H) {
    left.Resize(W, H);
    right.Resize(W, H);
    truth.Resize(W, H);
  }
};

// The right image at (xr, y) shows the texture point x_left = xr + d_right(xr, y).
inline SyntheticPair SlantedPlane(int W, int H, float a, float b, float c) {
  SyntheticPair p(W, H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      p.left.at(x, y) = static_cast<uint8_t>(std::lround(SlantedPlaneTexture(x, y)));
      p.truth.at(x, y) = a * x + b * y + c;
      const float dr = (a * x + b * y + c) / (1.0f - a);
      p.right.at(x, y) = static_cast<uint8_t>(std::lround(SlantedPlaneTexture(x + dr, y)));
    }
  return p;
}

// A fronto-parallel box at disparity `d_box` over the left view's
// [x0, x1) × [y0, y1) in front of a fronto-parallel wall at `d_wall` (a
// different texture). In the left view the wall's pixels in
// [x0 − (d_box − d_wall), x0) of the box's rows are hidden from the right
// camera (behind the box): no right pixel shows them.
// `wall_contrast` scales the wall's texture about its mid grey (below 1: a
// wall fainter than the box, as a projector's speckle fades with distance).
inline SyntheticPair BoxBeforeWall(int W, int H, int x0, int y0, int x1, int y1, float d_box, float d_wall,
                                   float wall_contrast = 1.0f) {
  SyntheticPair p(W, H);
  auto box_texture = [](float u, float v) { return SlantedPlaneTexture(u + 517.3f, v + 211.9f); };
  auto wall_texture = [&](float u, float v) { return 128.0f + wall_contrast * (SlantedPlaneTexture(u, v) - 128.0f); };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const bool in_rows = y >= y0 && y < y1;
      const bool box = in_rows && x >= x0 && x < x1;
      p.left.at(x, y) = static_cast<uint8_t>(std::lround(box ? box_texture(x, y) : wall_texture(x, y)));
      p.truth.at(x, y) = box ? d_box : d_wall;
      // Right pixel x shows the box where the box lands on it, else the wall.
      const float xb = static_cast<float>(x) + d_box;
      const bool right_box = in_rows && xb >= x0 && xb < x1;
      p.right.at(x, y) = static_cast<uint8_t>(
          std::lround(right_box ? box_texture(xb, y) : wall_texture(static_cast<float>(x) + d_wall, y)));
    }
  return p;
}

// A surface d(x, y) of the left view (any function whose x slope stays
// below 1, so that x − d(x, y) grows along a row), textured like the plane:
// the right pixel xr shows the texture point x_left with x_left − d(x_left,
// y) = xr, found by bisection in [xr, xr + max_d].
template <typename DisparityFn>
SyntheticPair CurvedSurface(int W, int H, float max_d, DisparityFn d) {
  SyntheticPair p(W, H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float fx = static_cast<float>(x), fy = static_cast<float>(y);
      p.left.at(x, y) = static_cast<uint8_t>(std::lround(SlantedPlaneTexture(fx, fy)));
      p.truth.at(x, y) = d(fx, fy);
      float lo = fx, hi = fx + max_d;
      for (int k = 0; k < 40; ++k) {
        const float mid = 0.5f * (lo + hi);
        (mid - d(mid, fy) < fx ? lo : hi) = mid;
      }
      p.right.at(x, y) = static_cast<uint8_t>(std::lround(SlantedPlaneTexture(0.5f * (lo + hi), fy)));
    }
  return p;
}

}  // namespace holo
