#include "client/render/gl_util.h"

#include <cstdio>
#include <vector>

#include <epoxy/gl.h>

namespace holo::render {
namespace {

StatusOr<GLuint> Compile(const std::string& name, GLenum type, const char* src) {
  GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetShaderiv(s, GL_INFO_LOG_LENGTH, &len);
    std::vector<char> log(static_cast<size_t>(len) + 1, '\0');
    glGetShaderInfoLog(s, len, nullptr, log.data());
    glDeleteShader(s);
    return Internal(name + ": " + (type == GL_VERTEX_SHADER ? "vertex" : "fragment") +
                    " shader does not compile: " + log.data());
  }
  return s;
}

}  // namespace

StatusOr<unsigned> BuildProgram(const std::string& name, const char* vertex_src, const char* fragment_src) {
  HOLO_ASSIGN_OR_RETURN(GLuint vs, Compile(name, GL_VERTEX_SHADER, vertex_src));
  auto fs = Compile(name, GL_FRAGMENT_SHADER, fragment_src);
  if (!fs.ok()) {
    glDeleteShader(vs);
    return fs.status();
  }
  GLuint p = glCreateProgram();
  glAttachShader(p, vs);
  glAttachShader(p, *fs);
  glLinkProgram(p);
  glDeleteShader(vs);
  glDeleteShader(*fs);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetProgramiv(p, GL_INFO_LOG_LENGTH, &len);
    std::vector<char> log(static_cast<size_t>(len) + 1, '\0');
    glGetProgramInfoLog(p, len, nullptr, log.data());
    glDeleteProgram(p);
    return Internal(name + ": program does not link: " + log.data());
  }
  return p;
}

Status CheckGlError(const std::string& where) {
  std::string errors;
  for (int i = 0; i < 8; ++i) {
    GLenum e = glGetError();
    if (e == GL_NO_ERROR) break;
    if (!errors.empty()) errors += ", ";
    errors += "0x" + [](unsigned v) {
      char buf[16];
      std::snprintf(buf, sizeof buf, "%04x", v);
      return std::string(buf);
    }(e);
  }
  if (errors.empty()) return OkStatus();
  return Internal(where + ": OpenGL error " + errors);
}

}  // namespace holo::render
