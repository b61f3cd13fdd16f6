#pragma once
// OpenGL context creation, in one place. Two back ends behind one interface:
//  - OSMesa (Mesa's off-screen software renderer; the default here, Mesa 22.3;
//    removed from Mesa 25.1 onward),
//  - EGL on the surfaceless platform (EGL_MESA_platform_surfaceless; llvmpipe
//    here, a GPU driver elsewhere), falling back to a pbuffer on the default
//    display.
// Both give an OpenGL 3.3 core context. Rendering always goes to a framebuffer
// object (see renderer.hpp), so the back ends differ only in how the context
// is made current and how GL entry points are looked up: the renderer calls
// GL through a function table filled from proc_address(), never through
// link-time GL symbols. That is why one binary can hold both back ends (libGL
// is not linked; libOSMesa and libEGL export no clashing symbols).
//
// Nothing here is real-time safe: creation allocates and may fail.

#include <memory>
#include <string>

namespace foresight::render {

enum class GlBackend { OSMesa, Egl };

/// "osmesa" or "egl"; throws std::invalid_argument naming the text otherwise.
GlBackend parse_gl_backend(const std::string& text);
const char* to_string(GlBackend backend);

struct GlContextOptions {
  int gl_major = 3;  ///< core profile version requested
  int gl_minor = 3;
};

class GlContext {
 public:
  virtual ~GlContext() = default;
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  virtual GlBackend backend() const = 0;
  /// Make the context current on the calling thread. Throws std::runtime_error.
  virtual void make_current() = 0;
  /// Address of a GL function (core or extension) for this context, nullptr
  /// when unknown.
  virtual void* proc_address(const char* name) const = 0;

  /// Create a context. Throws std::runtime_error saying which back end failed
  /// and why (e.g. the requested GL version is not available).
  static std::unique_ptr<GlContext> create(GlBackend backend, const GlContextOptions& options = {});

 protected:
  GlContext() = default;
};

}  // namespace foresight::render
