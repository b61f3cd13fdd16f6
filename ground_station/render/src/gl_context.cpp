#include "foresight/render/gl_context.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/osmesa.h>

#include <cstring>
#include <stdexcept>
#include <vector>

namespace foresight::render {

GlBackend parse_gl_backend(const std::string& text) {
  if (text == "osmesa") return GlBackend::OSMesa;
  if (text == "egl") return GlBackend::Egl;
  throw std::invalid_argument("GL back end '" + text + "' is not one of: osmesa, egl");
}

const char* to_string(GlBackend backend) { return backend == GlBackend::OSMesa ? "osmesa" : "egl"; }

namespace {

// The context this thread last made current through a GlContext. Every
// context switch in the process goes through make_current(), so a repeated
// call for the same context can return at once (OSMesaMakeCurrent costs
// ~1 ms a frame on llvmpipe). Not eglGetCurrentContext(): glvnd does not see
// an OSMesa context made current after an EGL one.
thread_local const GlContext* tls_current = nullptr;

std::string version_text(const GlContextOptions& o) {
  return "OpenGL " + std::to_string(o.gl_major) + "." + std::to_string(o.gl_minor) + " core profile";
}

// ---------------------------------------------------------------- OSMesa --
class OsMesaContext final : public GlContext {
 public:
  explicit OsMesaContext(const GlContextOptions& o) {
    const int attribs[] = {OSMESA_FORMAT,
                           OSMESA_RGBA,
                           OSMESA_DEPTH_BITS,
                           0,  // we render into our own framebuffer object
                           OSMESA_STENCIL_BITS,
                           0,
                           OSMESA_ACCUM_BITS,
                           0,
                           OSMESA_PROFILE,
                           OSMESA_CORE_PROFILE,
                           OSMESA_CONTEXT_MAJOR_VERSION,
                           o.gl_major,
                           OSMESA_CONTEXT_MINOR_VERSION,
                           o.gl_minor,
                           0};
    ctx_ = OSMesaCreateContextAttribs(attribs, nullptr);
    if (!ctx_) throw std::runtime_error("cannot create an OSMesa context for " + version_text(o));
  }
  ~OsMesaContext() override {
    if (tls_current == this) tls_current = nullptr;
    if (OSMesaGetCurrentContext() == ctx_) OSMesaMakeCurrent(nullptr, nullptr, 0, 0, 0);
    OSMesaDestroyContext(ctx_);
  }
  GlBackend backend() const override { return GlBackend::OSMesa; }
  void make_current() override {
    if (tls_current == this) return;
    // The default framebuffer is a 1x1 dummy; drawing goes to an FBO.
    if (!OSMesaMakeCurrent(ctx_, dummy_, GL_UNSIGNED_BYTE, 1, 1))
      throw std::runtime_error("OSMesaMakeCurrent failed");
    tls_current = this;
  }
  void* proc_address(const char* name) const override {
    return reinterpret_cast<void*>(OSMesaGetProcAddress(name));
  }

 private:
  OSMesaContext ctx_ = nullptr;
  unsigned char dummy_[4] = {0, 0, 0, 0};
};

// ------------------------------------------------------------------- EGL --
std::string egl_error_text(EGLint e) {
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

bool has_extension(const char* list, const char* name) {
  if (!list) return false;
  const std::size_t n = std::strlen(name);
  for (const char* p = std::strstr(list, name); p; p = std::strstr(p + 1, name))
    if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
  return false;
}

class EglContext final : public GlContext {
 public:
  explicit EglContext(const GlContextOptions& o) {
    std::string why;
    const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (has_extension(client_ext, "EGL_MESA_platform_surfaceless")) {
      if (try_open(eglGetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr), true, o, why))
        return;
    } else {
      why = "EGL_MESA_platform_surfaceless not offered";
    }
    // Fallback: a pbuffer on the default display (a GPU driver elsewhere).
    if (try_open(eglGetDisplay(EGL_DEFAULT_DISPLAY), false, o, why)) return;
    throw std::runtime_error("cannot create an EGL context for " + version_text(o) + ": " + why);
  }
  ~EglContext() override {
    if (tls_current == this) tls_current = nullptr;
    if (eglGetCurrentContext() == ctx_) eglMakeCurrent(dpy_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (surface_ != EGL_NO_SURFACE) eglDestroySurface(dpy_, surface_);
    eglDestroyContext(dpy_, ctx_);
    // No eglTerminate: the display is shared by every context of the process.
  }
  GlBackend backend() const override { return GlBackend::Egl; }
  void make_current() override {
    if (tls_current == this) return;
    if (!eglBindAPI(EGL_OPENGL_API) || !eglMakeCurrent(dpy_, surface_, surface_, ctx_))
      throw std::runtime_error("eglMakeCurrent failed: " + egl_error_text(eglGetError()));
    tls_current = this;
  }
  void* proc_address(const char* name) const override { return reinterpret_cast<void*>(eglGetProcAddress(name)); }

 private:
  bool try_open(EGLDisplay dpy, bool surfaceless, const GlContextOptions& o, std::string& why) {
    const std::string where = surfaceless ? "surfaceless display: " : "default display: ";
    auto fail = [&](const std::string& what) {
      why += (why.empty() ? "" : "; ") + where + what + " (" + egl_error_text(eglGetError()) + ")";
      return false;
    };
    if (dpy == EGL_NO_DISPLAY) return fail("no display");
    EGLint major = 0, minor = 0;
    if (!eglInitialize(dpy, &major, &minor)) return fail("eglInitialize failed");
    if (!eglBindAPI(EGL_OPENGL_API)) return fail("desktop OpenGL not supported");
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE,
                                     surfaceless ? 0 : EGL_PBUFFER_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint n = 0;
    if (!eglChooseConfig(dpy, config_attribs, &config, 1, &n) || n < 1) return fail("no OpenGL config");
    const EGLint ctx_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, o.gl_major, EGL_CONTEXT_MINOR_VERSION, o.gl_minor,
                                  EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, ctx_attribs);
    if (ctx == EGL_NO_CONTEXT) return fail("eglCreateContext failed");
    EGLSurface surface = EGL_NO_SURFACE;
    if (!surfaceless) {
      const EGLint pb_attribs[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
      surface = eglCreatePbufferSurface(dpy, config, pb_attribs);
      if (surface == EGL_NO_SURFACE) {
        eglDestroyContext(dpy, ctx);
        return fail("eglCreatePbufferSurface failed");
      }
    }
    dpy_ = dpy;
    ctx_ = ctx;
    surface_ = surface;
    return true;
  }

  EGLDisplay dpy_ = EGL_NO_DISPLAY;
  EGLContext ctx_ = EGL_NO_CONTEXT;
  EGLSurface surface_ = EGL_NO_SURFACE;
};

}  // namespace

std::unique_ptr<GlContext> GlContext::create(GlBackend backend, const GlContextOptions& options) {
  if (backend == GlBackend::OSMesa) return std::make_unique<OsMesaContext>(options);
  return std::make_unique<EglContext>(options);
}

}  // namespace foresight::render
