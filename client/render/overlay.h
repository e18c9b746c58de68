// Heads-up text overlay: a built-in 5×7 bitmap font (uppercase letters,
// digits, common punctuation; lowercase is drawn as uppercase) uploaded as a
// texture and drawn as one textured quad per character with alpha blending.
// Built in (not FreeType and a font file) so that the viewer needs no font
// on the machine and renders the same text everywhere.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/image.h"
#include "common/status.h"

namespace holo::render {

// The font: 5 columns × 7 rows per glyph, bit 4 of a row byte is the leftmost
// column. Unknown characters get a hollow box. Exposed for tests.
const std::array<uint8_t, 7>& Glyph5x7(char c);
bool HasGlyph(char c);

// Draws `text` into a CPU image (for tests and for images written without
// GL): top-left at (x, y), each font pixel a `scale`×`scale` block.
void DrawTextCpu(const std::string& text, int x, int y, int scale, const std::array<uint8_t, 3>& color,
                 ImageRgb8* image);

class Overlay {
 public:
  ~Overlay();
  // Needs a current 3.3 core context.
  static StatusOr<std::unique_ptr<Overlay>> Create();
  // Draws lines of text over the bound framebuffer of size fb_width × fb_height,
  // top-left at (x, y) pixels from the top-left corner, on a translucent dark
  // panel. '\n' starts a new line.
  Status Draw(const std::string& text, int x, int y, int scale, int fb_width, int fb_height,
              const std::array<uint8_t, 3>& color = {255, 255, 255});

 private:
  Overlay() = default;
  unsigned program_ = 0, texture_ = 0, vao_ = 0, vbo_ = 0;
};

}  // namespace holo::render
