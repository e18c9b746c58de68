// Pictures for people: depth colour maps and image mosaics (contact sheets).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/image.h"
#include "common/rgbd.h"

namespace holo {

// Depth (mm) as colour: near = warm, far = cool, invalid (0) = black.
ImageRgb8 ColorizeDepth(const ImageDepth16& depth, uint16_t near_mm, uint16_t far_mm);

// Colour image with the foreground of `mask` tinted (for checking masks by eye).
ImageRgb8 TintMask(const ImageRgb8& color, const ImageGray8& mask);

// Tiles images (any sizes) row by row into `columns` columns separated by
// `gap` pixels of dark grey; each cell is as large as the largest tile.
ImageRgb8 TileImages(const std::vector<const ImageRgb8*>& tiles, int columns, int gap = 4);

// Contact sheet of one frame set: for every group of `columns` pods a row of
// colour images, then a row of colourised depth (and, if masks are present
// and `with_masks`, a row of colour tinted by the mask).
ImageRgb8 MakeContactSheet(const RgbdFrameSet& frames, int columns = 4, bool with_masks = true);

}  // namespace holo
