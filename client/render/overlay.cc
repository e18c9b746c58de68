#include "client/render/overlay.h"

#include <algorithm>
#include <vector>

#include <epoxy/gl.h>

#include "client/render/gl_util.h"

namespace holo::render {
namespace {

constexpr int kCellW = 6, kCellH = 8;  // 5×7 glyph plus one column and row of spacing
constexpr int kLineH = 10;             // line pitch
constexpr int kAtlasGlyphs = 128;

constexpr const char* kVs = R"(#version 330 core
layout(location = 0) in vec2 a_px;   // pixels from the top-left corner
layout(location = 1) in vec2 a_uv;
uniform vec2 u_fb_size;
out vec2 v_uv;
void main() {
  v_uv = a_uv;
  gl_Position = vec4(2.0 * a_px.x / u_fb_size.x - 1.0, 1.0 - 2.0 * a_px.y / u_fb_size.y, 0.0, 1.0);
}
)";
constexpr const char* kFs = R"(#version 330 core
in vec2 v_uv;
out vec4 o_color;
uniform sampler2D u_font;
uniform vec4 u_color;
uniform int u_panel;
void main() {
  if (u_panel == 1) {
    o_color = vec4(0.0, 0.0, 0.0, 0.55);
    return;
  }
  float ink = texture(u_font, v_uv).r;
  if (ink < 0.5) discard;
  o_color = u_color;
}
)";

// Lays out `text` from (x, y) at `scale`: calls draw(c, cx, cy) with the top
// left corner of each character's cell ('\n' starts a new line).
template <typename Draw>
void LayOutText(const std::string& text, int x, int y, int scale, Draw draw) {
  int cx = x, cy = y;
  for (char c : text) {
    if (c == '\n') {
      cx = x;
      cy += kLineH * scale;
      continue;
    }
    draw(c, cx, cy);
    cx += kCellW * scale;
  }
}

}  // namespace

void DrawTextCpu(const std::string& text, int x, int y, int scale, const std::array<uint8_t, 3>& color,
                 ImageRgb8* image) {
  LayOutText(text, x, y, scale, [&](char c, int cx, int cy) {
    const auto& g = Glyph5x7(c);
    for (int r = 0; r < 7; ++r) {
      for (int col = 0; col < 5; ++col) {
        if (!(g[r] & (1u << (4 - col)))) continue;
        for (int dy = 0; dy < scale; ++dy) {
          for (int dx = 0; dx < scale; ++dx) {
            const int px = cx + col * scale + dx, py = cy + r * scale + dy;
            if (!image->Contains(px, py)) continue;
            for (int k = 0; k < 3; ++k) image->at(px, py, k) = color[k];
          }
        }
      }
    }
  });
}

Overlay::~Overlay() {
  if (program_) glDeleteProgram(program_);
  if (texture_) glDeleteTextures(1, &texture_);
  if (vbo_) glDeleteBuffers(1, &vbo_);
  if (vao_) glDeleteVertexArrays(1, &vao_);
}

StatusOr<std::unique_ptr<Overlay>> Overlay::Create() {
  std::unique_ptr<Overlay> o(new Overlay);
  HOLO_ASSIGN_OR_RETURN(o->program_, BuildProgram("overlay", kVs, kFs));
  // Atlas: glyph g in cell g of one row of 128 cells; texel row 0 = glyph row 0.
  const int aw = kAtlasGlyphs * kCellW, ah = kCellH;
  std::vector<uint8_t> atlas(static_cast<size_t>(aw) * ah, 0);
  for (int g = 0; g < kAtlasGlyphs; ++g) {
    const auto& bits = Glyph5x7(static_cast<char>(g));
    for (int r = 0; r < 7; ++r) {
      for (int c = 0; c < 5; ++c) {
        if (bits[r] & (1u << (4 - c))) atlas[static_cast<size_t>(r) * aw + g * kCellW + c] = 255;
      }
    }
  }
  glGenTextures(1, &o->texture_);
  glBindTexture(GL_TEXTURE_2D, o->texture_);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_R8, aw, ah, 0, GL_RED, GL_UNSIGNED_BYTE, atlas.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glBindTexture(GL_TEXTURE_2D, 0);
  glGenVertexArrays(1, &o->vao_);
  glGenBuffers(1, &o->vbo_);
  glBindVertexArray(o->vao_);
  glBindBuffer(GL_ARRAY_BUFFER, o->vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 4 * sizeof(float), nullptr);
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, 4 * sizeof(float), reinterpret_cast<void*>(2 * sizeof(float)));
  glBindVertexArray(0);
  HOLO_RETURN_IF_ERROR(CheckGlError("Overlay::Create"));
  return o;
}

Status Overlay::Draw(const std::string& text, int x, int y, int scale, int fb_width, int fb_height,
                     const std::array<uint8_t, 3>& color) {
  if (scale < 1 || fb_width <= 0 || fb_height <= 0) return InvalidArgument("overlay: bad scale or framebuffer size");
  std::vector<float> quads;  // 6 vertices × (x, y, u, v) per quad
  auto add_quad = [&quads](float x0, float y0, float x1, float y1, float u0, float v0, float u1, float v1) {
    const float q[6][4] = {{x0, y0, u0, v0}, {x1, y0, u1, v0}, {x1, y1, u1, v1},
                           {x0, y0, u0, v0}, {x1, y1, u1, v1}, {x0, y1, u0, v1}};
    for (const auto& v : q) quads.insert(quads.end(), v, v + 4);
  };
  // Panel around the text.
  int lines = 1, cols = 0, cur = 0;
  for (char c : text) {
    if (c == '\n') {
      ++lines;
      cur = 0;
    } else {
      cols = std::max(cols, ++cur);
    }
  }
  const float pad = 2.0f * scale;
  add_quad(x - pad, y - pad, x + cols * kCellW * scale + pad, y + (lines - 1) * kLineH * scale + 7 * scale + pad, 0, 0, 0,
           0);
  const float aw = static_cast<float>(kAtlasGlyphs * kCellW);
  LayOutText(text, x, y, scale, [&](char c, int cx, int cy) {
    // Atlas cell g holds Glyph5x7(g): lowercase cells already hold the
    // uppercase shapes, unknown ones the box.
    unsigned char g = static_cast<unsigned char>(c);
    if (g >= kAtlasGlyphs) g = 0;
    if (g != ' ') {
      const float u0 = g * kCellW / aw, u1 = (g * kCellW + 5) / aw;
      add_quad(static_cast<float>(cx), static_cast<float>(cy), static_cast<float>(cx + 5 * scale),
               static_cast<float>(cy + 7 * scale), u0, 0.0f, u1, 7.0f / kCellH);
    }
  });
  glViewport(0, 0, fb_width, fb_height);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_SCISSOR_TEST);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glUseProgram(program_);
  glUniform2f(glGetUniformLocation(program_, "u_fb_size"), static_cast<float>(fb_width), static_cast<float>(fb_height));
  glUniform4f(glGetUniformLocation(program_, "u_color"), color[0] / 255.0f, color[1] / 255.0f, color[2] / 255.0f, 1.0f);
  glUniform1i(glGetUniformLocation(program_, "u_font"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, texture_);
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(quads.size() * sizeof(float)), quads.data(), GL_STREAM_DRAW);
  glUniform1i(glGetUniformLocation(program_, "u_panel"), 1);
  glDrawArrays(GL_TRIANGLES, 0, 6);
  glUniform1i(glGetUniformLocation(program_, "u_panel"), 0);
  glDrawArrays(GL_TRIANGLES, 6, static_cast<GLsizei>(quads.size() / 4 - 6));
  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D, 0);
  glUseProgram(0);
  glDisable(GL_BLEND);
  glEnable(GL_DEPTH_TEST);
  return CheckGlError("Overlay::Draw");
}

}  // namespace holo::render
