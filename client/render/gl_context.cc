#include "client/render/gl_context.h"

#include <cstdlib>
#include <mutex>

#include <epoxy/egl.h>
#include <epoxy/gl.h>
// GLFW after epoxy: epoxy provides the GL declarations.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

namespace holo::render {
namespace {

std::string EglErrorName(EGLint e) {
  switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    default: return "EGL error " + std::to_string(e);
  }
}

class EglContext final : public GlContext {
 public:
  EglContext(EGLDisplay display, EGLContext context) : display_(display), context_(context) {}
  ~EglContext() override {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display_, context_);
    // The display is left initialised: Mesa shares it between contexts of
    // the process, and terminating it under another live context breaks that one.
  }
  Status MakeCurrent() override {
    if (!eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_)) {
      return Internal("eglMakeCurrent failed: " + EglErrorName(eglGetError()));
    }
    return OkStatus();
  }
  std::string Describe() const override { return "EGL surfaceless, " + CurrentGlRenderer(); }
  bool headless() const override { return true; }

 private:
  EGLDisplay display_;
  EGLContext context_;
};

std::mutex g_glfw_mutex;
int g_glfw_users = 0;

class GlfwContext final : public GlContext {
 public:
  explicit GlfwContext(GLFWwindow* w) : window_(w) {}
  ~GlfwContext() override {
    std::lock_guard<std::mutex> lock(g_glfw_mutex);
    glfwDestroyWindow(window_);
    if (--g_glfw_users == 0) glfwTerminate();
  }
  Status MakeCurrent() override {
    glfwMakeContextCurrent(window_);
    return OkStatus();
  }
  std::string Describe() const override { return "GLFW window, " + CurrentGlRenderer(); }
  GLFWwindow* window() override { return window_; }
  bool headless() const override { return false; }

 private:
  GLFWwindow* window_;
};

std::string g_glfw_error;
void GlfwErrorCallback(int code, const char* description) {
  g_glfw_error = "GLFW error " + std::to_string(code) + ": " + (description ? description : "?");
}

}  // namespace

StatusOr<std::unique_ptr<GlContext>> CreateHeadlessContext() {
  // Client extensions: EGL_EXT_platform_base + EGL_MESA_platform_surfaceless.
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (client_ext == nullptr || std::string(client_ext).find("EGL_MESA_platform_surfaceless") == std::string::npos) {
    return Unavailable(
        "headless rendering needs EGL with EGL_MESA_platform_surfaceless (Mesa's libEGL, package libegl-mesa0); "
        "this EGL does not offer it");
  }
  EGLDisplay display = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (display == EGL_NO_DISPLAY) {
    return Unavailable("eglGetPlatformDisplayEXT(surfaceless) failed: " + EglErrorName(eglGetError()));
  }
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) {
    return Unavailable("eglInitialize (surfaceless) failed: " + EglErrorName(eglGetError()));
  }
  if (!eglBindAPI(EGL_OPENGL_API)) return Unavailable("eglBindAPI(OpenGL) failed: " + EglErrorName(eglGetError()));
  const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint num_configs = 0;
  const bool have_config = eglChooseConfig(display, config_attribs, &config, 1, &num_configs) && num_configs > 0;
  const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                    3,
                                    EGL_CONTEXT_MINOR_VERSION,
                                    3,
                                    EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                    EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                    EGL_NONE};
  // Surfaceless contexts need no config (EGL_KHR_no_config_context) when none matches.
  EGLContext context =
      eglCreateContext(display, have_config ? config : EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, context_attribs);
  if (context == EGL_NO_CONTEXT) {
    return Unavailable("eglCreateContext (OpenGL 3.3 core) failed: " + EglErrorName(eglGetError()));
  }
  auto ctx = std::make_unique<EglContext>(display, context);
  if (Status s = ctx->MakeCurrent(); !s.ok()) return s;
  return std::unique_ptr<GlContext>(std::move(ctx));
}

StatusOr<std::unique_ptr<GlContext>> CreateWindowContext(int width, int height, const std::string& title,
                                                         bool visible) {
  if (width <= 0 || height <= 0) {
    return InvalidArgument("window size must be positive, got " + std::to_string(width) + "x" +
                           std::to_string(height));
  }
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((display == nullptr || *display == '\0') && (wayland == nullptr || *wayland == '\0')) {
    return Unavailable("no display: DISPLAY is not set (use --headless, or run under xvfb-run -a)");
  }
  std::lock_guard<std::mutex> lock(g_glfw_mutex);
  glfwSetErrorCallback(GlfwErrorCallback);
  if (g_glfw_users == 0) {
    g_glfw_error.clear();
    if (!glfwInit()) {
      return Unavailable("no display: GLFW could not initialise (" + g_glfw_error + "; DISPLAY=" +
                         (display ? display : "") + "); use --headless, or run under xvfb-run -a");
    }
  }
  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
  g_glfw_error.clear();
  GLFWwindow* w = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (w == nullptr) {
    if (g_glfw_users == 0) glfwTerminate();
    return Unavailable("could not open an OpenGL 3.3 core window: " + g_glfw_error);
  }
  ++g_glfw_users;
  glfwMakeContextCurrent(w);
  return std::unique_ptr<GlContext>(std::make_unique<GlfwContext>(w));
}

namespace {
bool AnyContextCurrent() {
  if (eglGetCurrentContext() != EGL_NO_CONTEXT) return true;
  std::lock_guard<std::mutex> lock(g_glfw_mutex);
  return g_glfw_users > 0 && glfwGetCurrentContext() != nullptr;
}
}  // namespace

void FinishGl() { glFinish(); }

std::string CurrentGlRenderer() {
  if (!AnyContextCurrent()) return "";
  const GLubyte* s = glGetString(GL_RENDERER);
  return s ? reinterpret_cast<const char*>(s) : "";
}
std::string CurrentGlVersion() {
  if (!AnyContextCurrent()) return "";
  const GLubyte* s = glGetString(GL_VERSION);
  return s ? reinterpret_cast<const char*>(s) : "";
}

}  // namespace holo::render
