// OpenGL 3.3 core contexts for the viewer: a headless one (EGL surfaceless on
// Mesa, no X server needed; rendering goes into framebuffer objects) and a
// GLFW window (interactive). GL functions are resolved through libepoxy,
// which works under both EGL and GLX.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "common/status.h"

struct GLFWwindow;

namespace holo::render {

class GlContext {
 public:
  virtual ~GlContext() = default;
  // Makes the context current on the calling thread.
  virtual Status MakeCurrent() = 0;
  // "EGL surfaceless" or "GLFW window"; plus GL_RENDERER / GL_VERSION once current.
  virtual std::string Describe() const = 0;
  // Window only (null for headless).
  virtual GLFWwindow* window() { return nullptr; }
  virtual bool headless() const = 0;
};

// Headless context: EGL on the Mesa surfaceless platform (OpenGL 3.3 core).
// Errors name what failed ("no EGL surfaceless platform", "eglCreateContext
// failed: EGL_BAD_MATCH", ...) and never crash.
StatusOr<std::unique_ptr<GlContext>> CreateHeadlessContext();

// Window with an OpenGL 3.3 core context. Fails with Unavailable and a clear
// message when there is no display (DISPLAY / WAYLAND_DISPLAY unset, or the X
// server cannot be opened): "no display: DISPLAY is not set (use --headless,
// or run under xvfb-run -a)".
StatusOr<std::unique_ptr<GlContext>> CreateWindowContext(int width, int height, const std::string& title,
                                                         bool visible = true);

// glFinish on the current context: waits until all submitted GL work is
// done (for timing).
void FinishGl();

// GL_RENDERER and GL_VERSION of the current context, "" if none is current.
std::string CurrentGlRenderer();
std::string CurrentGlVersion();

}  // namespace holo::render
