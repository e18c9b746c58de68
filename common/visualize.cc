#include "common/visualize.h"

#include <algorithm>
#include <cmath>

namespace holo {

namespace {
// A perceptually ordered warm→cool ramp (piecewise linear through 5 stops).
void Ramp(float t, uint8_t* rgb) {
  static const float kStops[5][3] = {
      {255, 240, 60}, {250, 130, 30}, {210, 40, 80}, {90, 40, 160}, {20, 60, 140}};
  t = std::clamp(t, 0.0f, 1.0f) * 4.0f;
  const int i = std::min(3, static_cast<int>(t));
  const float f = t - static_cast<float>(i);
  for (int c = 0; c < 3; ++c)
    rgb[c] = static_cast<uint8_t>(std::lround(kStops[i][c] * (1 - f) + kStops[i + 1][c] * f));
}
}  // namespace

ImageRgb8 ColorizeDepth(const ImageDepth16& depth, uint16_t near_mm, uint16_t far_mm) {
  ImageRgb8 out(depth.width(), depth.height(), 0);
  const float range = std::max(1.0f, static_cast<float>(far_mm) - static_cast<float>(near_mm));
  for (int y = 0; y < depth.height(); ++y)
    for (int x = 0; x < depth.width(); ++x) {
      const uint16_t d = depth.at(x, y);
      if (d == 0) continue;
      Ramp((static_cast<float>(d) - near_mm) / range, &out.at(x, y, 0));
    }
  return out;
}

ImageRgb8 TintMask(const ImageRgb8& color, const ImageGray8& mask) {
  ImageRgb8 out = color;
  if (mask.width() != color.width() || mask.height() != color.height()) return out;
  for (int y = 0; y < color.height(); ++y)
    for (int x = 0; x < color.width(); ++x) {
      uint8_t* p = &out.at(x, y, 0);
      if (mask.at(x, y)) {
        p[1] = static_cast<uint8_t>(std::min(255, p[1] / 2 + 128));
      } else {
        for (int c = 0; c < 3; ++c) p[c] = static_cast<uint8_t>(p[c] / 3);
      }
    }
  return out;
}

ImageRgb8 TileImages(const std::vector<const ImageRgb8*>& tiles, int columns, int gap) {
  if (tiles.empty() || columns <= 0) return {};
  int cw = 0, ch = 0;
  for (const auto* t : tiles) {
    cw = std::max(cw, t->width());
    ch = std::max(ch, t->height());
  }
  const int n = static_cast<int>(tiles.size());
  const int cols = std::min(columns, n);
  const int rows = (n + cols - 1) / cols;
  ImageRgb8 out(cols * cw + (cols + 1) * gap, rows * ch + (rows + 1) * gap, 40);
  for (int i = 0; i < n; ++i) {
    const ImageRgb8& t = *tiles[static_cast<size_t>(i)];
    const int ox = gap + (i % cols) * (cw + gap), oy = gap + (i / cols) * (ch + gap);
    for (int y = 0; y < t.height(); ++y) std::copy(t.row(y), t.row(y) + 3 * t.width(), out.row(oy + y) + 3 * ox);
  }
  return out;
}

ImageRgb8 MakeContactSheet(const RgbdFrameSet& frames, int columns, bool with_masks) {
  std::vector<ImageRgb8> depth_images, mask_images;
  depth_images.reserve(frames.frames.size());
  mask_images.reserve(frames.frames.size());
  bool have_masks = with_masks;
  for (const auto& f : frames.frames) {
    depth_images.push_back(ColorizeDepth(f.depth, 1000, 5500));
    if (f.mask.empty()) have_masks = false;
  }
  if (have_masks)
    for (const auto& f : frames.frames) mask_images.push_back(TintMask(f.color, f.mask));
  std::vector<const ImageRgb8*> tiles;
  const size_t n = frames.frames.size();
  const size_t cols = static_cast<size_t>(std::max(1, columns));
  for (size_t start = 0; start < n; start += cols) {
    const size_t end = std::min(n, start + cols);
    // Pad short groups so rows stay aligned.
    auto add_row = [&](auto get) {
      for (size_t i = start; i < start + cols; ++i) tiles.push_back(i < end ? get(i) : nullptr);
    };
    add_row([&](size_t i) { return &frames.frames[i].color; });
    add_row([&](size_t i) { return &depth_images[i]; });
    if (have_masks) add_row([&](size_t i) { return &mask_images[i]; });
  }
  static const ImageRgb8 kEmpty;
  for (auto& t : tiles)
    if (t == nullptr) t = &kEmpty;
  return TileImages(tiles, static_cast<int>(cols));
}

}  // namespace holo
