// Dense images: row-major, interleaved channels, owning their pixels.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/status.h"

namespace holo {

template <typename T, int C>
class Image {
 public:
  using value_type = T;
  static constexpr int kChannels = C;

  Image() = default;
  Image(int width, int height, T fill = T{}) { Resize(width, height, fill); }

  void Resize(int width, int height, T fill = T{}) {
    HOLO_CHECK(width >= 0 && height >= 0);
    width_ = width;
    height_ = height;
    data_.assign(static_cast<size_t>(width) * height * C, fill);
  }
  void Fill(T v) { std::fill(data_.begin(), data_.end(), v); }

  int width() const { return width_; }
  int height() const { return height_; }
  bool empty() const { return data_.empty(); }
  size_t num_pixels() const { return static_cast<size_t>(width_) * height_; }
  bool Contains(int x, int y) const { return x >= 0 && y >= 0 && x < width_ && y < height_; }

  T* data() { return data_.data(); }
  const T* data() const { return data_.data(); }
  T* row(int y) { return data_.data() + static_cast<size_t>(y) * width_ * C; }
  const T* row(int y) const { return data_.data() + static_cast<size_t>(y) * width_ * C; }
  T& at(int x, int y, int c = 0) { return data_[(static_cast<size_t>(y) * width_ + x) * C + c]; }
  const T& at(int x, int y, int c = 0) const { return data_[(static_cast<size_t>(y) * width_ + x) * C + c]; }
  std::vector<T>& storage() { return data_; }
  const std::vector<T>& storage() const { return data_; }

  bool operator==(const Image& o) const { return width_ == o.width_ && height_ == o.height_ && data_ == o.data_; }

 private:
  int width_ = 0;
  int height_ = 0;
  std::vector<T> data_;
};

using ImageRgb8 = Image<uint8_t, 3>;   // 8-bit RGB (R first)
using ImageGray8 = Image<uint8_t, 1>;  // masks: 0 = background, 255 = foreground
using ImageDepth16 = Image<uint16_t, 1>;  // depth in millimetres, 0 = invalid
using ImageFloat = Image<float, 1>;

}  // namespace holo
