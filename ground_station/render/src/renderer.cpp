#include "foresight/render/renderer.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "gl_functions.hpp"

namespace foresight::render {

RenderMode parse_render_mode(const std::string& text) {
  if (text == "wire") return RenderMode::Wire;
  if (text == "solid") return RenderMode::Solid;
  if (text == "hidden") return RenderMode::Hidden;
  if (text == "ghost") return RenderMode::Ghost;
  throw std::invalid_argument("render mode '" + text + "' is not one of: wire, solid, hidden, ghost");
}

const char* to_string(RenderMode mode) {
  switch (mode) {
    case RenderMode::Wire: return "wire";
    case RenderMode::Solid: return "solid";
    case RenderMode::Hidden: return "hidden";
    case RenderMode::Ghost: return "ghost";
  }
  return "?";
}

void append_triad(DrawList& list, const Pose& T, double length_m) {
  const Eigen::Vector3d o = T.translation();
  for (int axis = 0; axis < 3; ++axis) {
    LineSet s;
    s.strip = false;
    s.points_base = {o, o + length_m * T.linear().col(axis)};
    s.rgba = Eigen::Vector4d(axis == 0, axis == 1, axis == 2, 1.0);
    if (axis == 2) s.rgba = {0.2, 0.4, 1.0, 1.0};  // pure blue is hard to see on dark video
    list.lines.push_back(std::move(s));
  }
}

namespace {

const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_rgba;
uniform mat4 u_mvp;
uniform mat4 u_mv;
out vec3 v_normal_eye;
out vec4 v_rgba;
void main() {
  gl_Position = u_mvp * vec4(a_position, 1.0);
  v_normal_eye = mat3(u_mv) * a_normal;
  v_rgba = a_rgba;
}
)";

// Lighting in the eye frame (looking down -z): a key light from the upper
// right of the camera, two-sided, plus ambient.
const char* kFragmentShader = R"(#version 330 core
in vec3 v_normal_eye;
in vec4 v_rgba;
uniform vec4 u_color;
uniform int u_use_color;
uniform int u_lighting;
out vec4 o_color;
void main() {
  vec4 c = (u_use_color != 0) ? u_color : v_rgba;
  if (u_lighting != 0) {
    vec3 n = normalize(v_normal_eye);
    float d = abs(dot(n, normalize(vec3(0.35, 0.55, 1.0))));
    c.rgb *= 0.28 + 0.72 * d;
  }
  o_color = vec4(c.rgb, 1.0);
}
)";

void to_float(const Eigen::Matrix4d& M, float out[16]) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) out[c * 4 + r] = static_cast<float>(M(r, c));  // column-major
}

}  // namespace

struct Renderer::Impl {
  GlContext& ctx;
  camera::Viewport vp;
  int samples = 1;
  detail::GlFunctions gl;
  GLuint program = 0, vao = 0, vbo = 0, ebo = 0, line_vao = 0, line_vbo = 0;
  GLuint fbo = 0, color_rb = 0, depth_rb = 0;        // render target (multisample when samples > 1)
  GLuint resolve_fbo = 0, resolve_rb = 0;            // single-sample copy for read-back
  GLint u_mvp = -1, u_mv = -1, u_color = -1, u_use_color = -1, u_lighting = -1;
  struct Body {
    std::size_t triangle_offset = 0, triangle_indices = 0, edge_offset = 0, edge_indices = 0;
  };
  std::vector<Body> bodies;
  std::vector<Vertex> vertices;
  std::vector<std::uint32_t> triangle_indices, edge_indices;  // edges stored after triangles in the EBO
  std::vector<Vertex> line_vertices;

  Impl(GlContext& c, const camera::Viewport& v, int s) : ctx(c), vp(v), samples(std::max(1, s)) {}

  void check(const char* what) {
    const GLenum e = gl.GetError();
    if (e != GL_NO_ERROR)
      throw std::runtime_error(std::string("OpenGL error 0x") + [&] {
        char b[16];
        std::snprintf(b, sizeof b, "%04x", e);
        return std::string(b);
      }() + " during " + what + " (" + to_string(ctx.backend()) + ")");
  }

  GLuint compile(GLenum type, const char* src) {
    const GLuint s = gl.CreateShader(type);
    gl.ShaderSource(s, 1, &src, nullptr);
    gl.CompileShader(s);
    GLint ok = 0;
    gl.GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char log[2048];
      gl.GetShaderInfoLog(s, sizeof log, nullptr, log);
      throw std::runtime_error(std::string("shader compilation failed: ") + log);
    }
    return s;
  }

  void setup() {
    ctx.make_current();
    gl.load(ctx);
    GLint max_rb = 0, max_dims[2] = {0, 0};
    gl.GetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_rb);
    gl.GetIntegerv(GL_MAX_VIEWPORT_DIMS, max_dims);
    const int limit = std::min({max_rb, max_dims[0], max_dims[1]});
    if (vp.width_px <= 0 || vp.height_px <= 0 || vp.width_px > limit || vp.height_px > limit)
      throw std::runtime_error("viewport " + std::to_string(vp.width_px) + "x" + std::to_string(vp.height_px) +
                               " cannot be rendered: the " + to_string(ctx.backend()) + " GL limit is " +
                               std::to_string(limit) + " pixels a side");
    GLint max_samples = 1;
    gl.GetIntegerv(GL_MAX_SAMPLES, &max_samples);
    samples = std::min(samples, std::max(1, static_cast<int>(max_samples)));

    const GLuint vs = compile(GL_VERTEX_SHADER, kVertexShader);
    const GLuint fs = compile(GL_FRAGMENT_SHADER, kFragmentShader);
    program = gl.CreateProgram();
    gl.AttachShader(program, vs);
    gl.AttachShader(program, fs);
    gl.LinkProgram(program);
    gl.DeleteShader(vs);
    gl.DeleteShader(fs);
    GLint ok = 0;
    gl.GetProgramiv(program, GL_LINK_STATUS, &ok);
    if (!ok) {
      char log[2048];
      gl.GetProgramInfoLog(program, sizeof log, nullptr, log);
      throw std::runtime_error(std::string("shader link failed: ") + log);
    }
    u_mvp = gl.GetUniformLocation(program, "u_mvp");
    u_mv = gl.GetUniformLocation(program, "u_mv");
    u_color = gl.GetUniformLocation(program, "u_color");
    u_use_color = gl.GetUniformLocation(program, "u_use_color");
    u_lighting = gl.GetUniformLocation(program, "u_lighting");

    auto setup_vao = [&](GLuint& vao_id, GLuint& vbo_id) {
      gl.GenVertexArrays(1, &vao_id);
      gl.BindVertexArray(vao_id);
      gl.GenBuffers(1, &vbo_id);
      gl.BindBuffer(GL_ARRAY_BUFFER, vbo_id);
      gl.EnableVertexAttribArray(0);
      gl.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(Vertex), reinterpret_cast<void*>(offsetof(Vertex, position)));
      gl.EnableVertexAttribArray(1);
      gl.VertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(Vertex), reinterpret_cast<void*>(offsetof(Vertex, normal)));
      gl.EnableVertexAttribArray(2);
      gl.VertexAttribPointer(2, 4, GL_FLOAT, GL_FALSE, sizeof(Vertex), reinterpret_cast<void*>(offsetof(Vertex, rgba)));
    };
    setup_vao(vao, vbo);
    gl.GenBuffers(1, &ebo);
    gl.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo);  // part of the VAO state
    setup_vao(line_vao, line_vbo);
    gl.BindVertexArray(0);

    auto make_target = [&](GLuint& fb, GLuint& color, GLuint* depth, int n_samples) {
      gl.GenFramebuffers(1, &fb);
      gl.BindFramebuffer(GL_FRAMEBUFFER, fb);
      gl.GenRenderbuffers(1, &color);
      gl.BindRenderbuffer(GL_RENDERBUFFER, color);
      gl.RenderbufferStorageMultisample(GL_RENDERBUFFER, n_samples > 1 ? n_samples : 0, GL_RGBA8, vp.width_px, vp.height_px);
      gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color);
      if (depth) {
        gl.GenRenderbuffers(1, depth);
        gl.BindRenderbuffer(GL_RENDERBUFFER, *depth);
        gl.RenderbufferStorageMultisample(GL_RENDERBUFFER, n_samples > 1 ? n_samples : 0, GL_DEPTH_COMPONENT24,
                                          vp.width_px, vp.height_px);
        gl.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, *depth);
      }
      const GLenum status = gl.CheckFramebufferStatus(GL_FRAMEBUFFER);
      if (status != GL_FRAMEBUFFER_COMPLETE)
        throw std::runtime_error("framebuffer " + std::to_string(vp.width_px) + "x" + std::to_string(vp.height_px) +
                                 " is incomplete (status " + std::to_string(status) + ")");
    };
    make_target(fbo, color_rb, &depth_rb, samples);
    if (samples > 1) make_target(resolve_fbo, resolve_rb, nullptr, 1);
    check("renderer set-up");
  }

  void upload() {
    std::vector<std::uint32_t> all = triangle_indices;
    all.insert(all.end(), edge_indices.begin(), edge_indices.end());
    gl.BindVertexArray(vao);
    gl.BindBuffer(GL_ARRAY_BUFFER, vbo);
    gl.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices.size() * sizeof(Vertex)), vertices.data(), GL_STATIC_DRAW);
    gl.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(all.size() * sizeof(std::uint32_t)), all.data(),
                  GL_STATIC_DRAW);
    gl.BindVertexArray(0);
    check("mesh upload");
  }
};

Renderer::Renderer(GlContext& context, const camera::Viewport& viewport, int samples)
    : impl_(std::make_unique<Impl>(context, viewport, samples)) {
  impl_->setup();
}

Renderer::~Renderer() {
  auto& I = *impl_;
  try {
    I.ctx.make_current();
  } catch (...) {
    return;  // the context is gone; its objects with it
  }
  auto& gl = I.gl;
  gl.DeleteFramebuffers(1, &I.fbo);
  gl.DeleteRenderbuffers(1, &I.color_rb);
  gl.DeleteRenderbuffers(1, &I.depth_rb);
  if (I.resolve_fbo) {
    gl.DeleteFramebuffers(1, &I.resolve_fbo);
    gl.DeleteRenderbuffers(1, &I.resolve_rb);
  }
  gl.DeleteBuffers(1, &I.vbo);
  gl.DeleteBuffers(1, &I.ebo);
  gl.DeleteBuffers(1, &I.line_vbo);
  gl.DeleteVertexArrays(1, &I.vao);
  gl.DeleteVertexArrays(1, &I.line_vao);
  gl.DeleteProgram(I.program);
}

int Renderer::add_body(const Mesh& mesh) {
  auto& I = *impl_;
  I.ctx.make_current();
  const auto base = static_cast<std::uint32_t>(I.vertices.size());
  I.vertices.insert(I.vertices.end(), mesh.vertices.begin(), mesh.vertices.end());
  Impl::Body b;
  b.triangle_offset = I.triangle_indices.size();
  b.triangle_indices = mesh.triangles.size();
  for (auto i : mesh.triangles) I.triangle_indices.push_back(base + i);
  b.edge_offset = I.edge_indices.size();
  b.edge_indices = mesh.edges.size();
  for (auto i : mesh.edges) I.edge_indices.push_back(base + i);
  I.bodies.push_back(b);
  I.upload();
  return static_cast<int>(I.bodies.size()) - 1;
}

int Renderer::body_triangles(int body) const {
  if (body < 0 || body >= static_cast<int>(impl_->bodies.size()))
    throw std::invalid_argument("unknown body " + std::to_string(body));
  return static_cast<int>(impl_->bodies[body].triangle_indices / 3);
}

const camera::Viewport& Renderer::viewport() const { return impl_->vp; }
GlContext& Renderer::context() { return impl_->ctx; }

std::string Renderer::gl_description() const {
  auto& I = *impl_;
  I.ctx.make_current();
  auto s = [&](GLenum e) {
    const GLubyte* p = I.gl.GetString(e);
    return p ? std::string(reinterpret_cast<const char*>(p)) : std::string("?");
  };
  return s(GL_RENDERER) + ", " + s(GL_VERSION);
}

int Renderer::render(const camera::Camera& camera, const DrawList& list, const RenderSettings& st, cv::Mat& layer) {
  auto& I = *impl_;
  auto& gl = I.gl;
  if (!(camera.viewport == I.vp))
    throw std::invalid_argument("camera '" + camera.name + "' viewport " + std::to_string(camera.viewport.width_px) + "x" +
                                std::to_string(camera.viewport.height_px) + " differs from the renderer's " +
                                std::to_string(I.vp.width_px) + "x" + std::to_string(I.vp.height_px));
  for (const auto& b : list.bodies)
    if (b.body < 0 || b.body >= static_cast<int>(I.bodies.size()))
      throw std::invalid_argument("unknown body " + std::to_string(b.body));

  I.ctx.make_current();
  gl.BindFramebuffer(GL_FRAMEBUFFER, I.fbo);
  gl.Viewport(0, 0, I.vp.width_px, I.vp.height_px);
  gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  gl.DepthMask(GL_TRUE);
  gl.ClearColor(static_cast<float>(st.clear_rgba[0]), static_cast<float>(st.clear_rgba[1]),
                static_cast<float>(st.clear_rgba[2]), static_cast<float>(st.clear_rgba[3]));
  gl.Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  gl.UseProgram(I.program);
  gl.LineWidth(st.line_width_px);

  // The camera's projection, then a flip of window y so GL rows are image rows from the top.
  const Eigen::Matrix4d flip = Eigen::Vector4d(1.0, -1.0, 1.0, 1.0).asDiagonal();
  const Eigen::Matrix4d P = flip * camera.gl_projection(st.near_m, st.far_m);
  const Eigen::Matrix4d V = camera.gl_view();
  float m16[16];
  auto set_transform = [&](const Eigen::Matrix4d& base_T_x) {
    const Eigen::Matrix4d MV = V * base_T_x;
    to_float(P * MV, m16);
    gl.UniformMatrix4fv(I.u_mvp, 1, GL_FALSE, m16);
    to_float(MV, m16);
    gl.UniformMatrix4fv(I.u_mv, 1, GL_FALSE, m16);
  };
  auto set_color = [&](const std::optional<Eigen::Vector4d>& c) {
    gl.Uniform1i(I.u_use_color, c ? 1 : 0);
    if (c) {
      const float f[4] = {static_cast<float>((*c)[0]), static_cast<float>((*c)[1]), static_cast<float>((*c)[2]),
                          static_cast<float>((*c)[3])};
      gl.Uniform4fv(I.u_color, 1, f);
    }
  };
  const std::size_t edge_base = I.triangle_indices.size();
  auto draw_triangles = [&](const Impl::Body& b) {
    gl.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(b.triangle_indices), GL_UNSIGNED_INT,
                    reinterpret_cast<void*>(b.triangle_offset * sizeof(std::uint32_t)));
  };
  auto draw_edges = [&](const Impl::Body& b) {
    gl.DrawElements(GL_LINES, static_cast<GLsizei>(b.edge_indices), GL_UNSIGNED_INT,
                    reinterpret_cast<void*>((edge_base + b.edge_offset) * sizeof(std::uint32_t)));
  };

  int triangles = 0;
  gl.BindVertexArray(I.vao);
  switch (st.mode) {
    case RenderMode::Solid:
    case RenderMode::Ghost:
      gl.Enable(GL_DEPTH_TEST);
      gl.DepthFunc(GL_LESS);
      gl.Uniform1i(I.u_lighting, st.lighting ? 1 : 0);
      for (const auto& b : list.bodies) {
        set_transform(b.base_T_body.matrix());
        set_color(b.solid_rgba);
        draw_triangles(I.bodies[b.body]);
        triangles += static_cast<int>(I.bodies[b.body].triangle_indices / 3);
      }
      break;
    case RenderMode::Wire:
      gl.Disable(GL_DEPTH_TEST);
      gl.Uniform1i(I.u_lighting, 0);
      for (const auto& b : list.bodies) {
        set_transform(b.base_T_body.matrix());
        set_color(b.wire_rgba);
        draw_edges(I.bodies[b.body]);
      }
      break;
    case RenderMode::Hidden:
      // Depth-only pass of the faces, pushed back so the edges on them pass.
      gl.Enable(GL_DEPTH_TEST);
      gl.DepthFunc(GL_LESS);
      gl.ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      gl.Enable(GL_POLYGON_OFFSET_FILL);
      gl.PolygonOffset(1.0f, 1.0f);
      gl.Uniform1i(I.u_lighting, 0);
      for (const auto& b : list.bodies) {
        set_transform(b.base_T_body.matrix());
        draw_triangles(I.bodies[b.body]);
        triangles += static_cast<int>(I.bodies[b.body].triangle_indices / 3);
      }
      gl.Disable(GL_POLYGON_OFFSET_FILL);
      gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      gl.DepthFunc(GL_LEQUAL);
      gl.DepthMask(GL_FALSE);
      for (const auto& b : list.bodies) {
        set_transform(b.base_T_body.matrix());
        set_color(b.wire_rgba);
        draw_edges(I.bodies[b.body]);
      }
      gl.DepthMask(GL_TRUE);
      break;
  }

  // Line sets (triads, tool paths): on top of everything.
  if (!list.lines.empty()) {
    I.line_vertices.clear();
    for (const auto& s : list.lines)
      for (const auto& p : s.points_base) {
        Vertex v{};
        for (int i = 0; i < 3; ++i) v.position[i] = static_cast<float>(p[i]);
        for (int i = 0; i < 4; ++i) v.rgba[i] = static_cast<float>(s.rgba[i]);
        I.line_vertices.push_back(v);
      }
    gl.Disable(GL_DEPTH_TEST);
    gl.BindVertexArray(I.line_vao);
    gl.BindBuffer(GL_ARRAY_BUFFER, I.line_vbo);
    gl.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(I.line_vertices.size() * sizeof(Vertex)),
                  I.line_vertices.data(), GL_STREAM_DRAW);
    gl.Uniform1i(I.u_lighting, 0);
    gl.Uniform1i(I.u_use_color, 0);
    set_transform(Eigen::Matrix4d::Identity());
    GLint first = 0;
    for (const auto& s : list.lines) {
      const auto n = static_cast<GLsizei>(s.points_base.size());
      gl.LineWidth(s.width_px);
      gl.DrawArrays(s.strip ? GL_LINE_STRIP : GL_LINES, first, n);
      first += n;
    }
  }
  gl.BindVertexArray(0);

  // Read back (top row first, thanks to the flip above).
  if (I.resolve_fbo) {
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, I.fbo);
    gl.BindFramebuffer(GL_DRAW_FRAMEBUFFER, I.resolve_fbo);
    gl.BlitFramebuffer(0, 0, I.vp.width_px, I.vp.height_px, 0, 0, I.vp.width_px, I.vp.height_px, GL_COLOR_BUFFER_BIT,
                       GL_NEAREST);
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, I.resolve_fbo);
  } else {
    gl.BindFramebuffer(GL_READ_FRAMEBUFFER, I.fbo);
  }
  layer.create(I.vp.height_px, I.vp.width_px, CV_8UC4);
  gl.PixelStorei(GL_PACK_ALIGNMENT, 4);
  gl.ReadPixels(0, 0, I.vp.width_px, I.vp.height_px, GL_BGRA, GL_UNSIGNED_BYTE, layer.data);
  I.check("render");
  return triangles;
}

void composite(const cv::Mat& layer, double opacity, cv::Mat& video) {
  if (layer.type() != CV_8UC4 || video.type() != CV_8UC3 || layer.size() != video.size())
    throw std::invalid_argument("composite: layer (BGRA) and video (BGR) must have the same size");
  const float opacity_f = static_cast<float>(std::clamp(opacity, 0.0, 1.0)) / 255.0f;
  for (int r = 0; r < layer.rows; ++r) {
    const std::uint8_t* l = layer.ptr<std::uint8_t>(r);
    std::uint8_t* v = video.ptr<std::uint8_t>(r);
    for (int c = 0; c < layer.cols; ++c, l += 4, v += 3) {
      if (l[3] == 0) continue;
      const float a = opacity_f * static_cast<float>(l[3]);
      for (int k = 0; k < 3; ++k)
        v[k] = static_cast<std::uint8_t>(static_cast<float>(l[k]) * a + static_cast<float>(v[k]) * (1.0f - a) + 0.5f);
    }
  }
}

}  // namespace foresight::render
