#pragma once
// The GL entry points the renderer uses, looked up through the context's
// proc_address() (OSMesaGetProcAddress or eglGetProcAddress) rather than
// linked: the same renderer code runs on either back end, and no libGL is
// linked beside libOSMesa.

#include <GL/glcorearb.h>

#include <stdexcept>
#include <string>

#include "foresight/render/gl_context.hpp"

namespace foresight::render::detail {

#define FORESIGHT_GL_FUNCTIONS(X)                                         \
  X(GETERROR, GetError)                                                   \
  X(GETSTRING, GetString)                                                 \
  X(GETINTEGERV, GetIntegerv)                                             \
  X(VIEWPORT, Viewport)                                                   \
  X(CLEARCOLOR, ClearColor)                                               \
  X(CLEAR, Clear)                                                         \
  X(ENABLE, Enable)                                                       \
  X(DISABLE, Disable)                                                     \
  X(DEPTHFUNC, DepthFunc)                                                 \
  X(DEPTHMASK, DepthMask)                                                 \
  X(COLORMASK, ColorMask)                                                 \
  X(POLYGONOFFSET, PolygonOffset)                                         \
  X(LINEWIDTH, LineWidth)                                                 \
  X(READPIXELS, ReadPixels)                                               \
  X(PIXELSTOREI, PixelStorei)                                             \
  X(READBUFFER, ReadBuffer)                                               \
  X(DRAWELEMENTS, DrawElements)                                           \
  X(DRAWARRAYS, DrawArrays)                                               \
  X(GENBUFFERS, GenBuffers)                                               \
  X(DELETEBUFFERS, DeleteBuffers)                                         \
  X(BINDBUFFER, BindBuffer)                                               \
  X(BUFFERDATA, BufferData)                                               \
  X(GENVERTEXARRAYS, GenVertexArrays)                                     \
  X(DELETEVERTEXARRAYS, DeleteVertexArrays)                               \
  X(BINDVERTEXARRAY, BindVertexArray)                                     \
  X(ENABLEVERTEXATTRIBARRAY, EnableVertexAttribArray)                     \
  X(VERTEXATTRIBPOINTER, VertexAttribPointer)                             \
  X(CREATESHADER, CreateShader)                                           \
  X(SHADERSOURCE, ShaderSource)                                           \
  X(COMPILESHADER, CompileShader)                                         \
  X(GETSHADERIV, GetShaderiv)                                             \
  X(GETSHADERINFOLOG, GetShaderInfoLog)                                   \
  X(DELETESHADER, DeleteShader)                                           \
  X(CREATEPROGRAM, CreateProgram)                                         \
  X(ATTACHSHADER, AttachShader)                                           \
  X(BINDATTRIBLOCATION, BindAttribLocation)                               \
  X(LINKPROGRAM, LinkProgram)                                             \
  X(GETPROGRAMIV, GetProgramiv)                                           \
  X(GETPROGRAMINFOLOG, GetProgramInfoLog)                                 \
  X(DELETEPROGRAM, DeleteProgram)                                         \
  X(USEPROGRAM, UseProgram)                                               \
  X(GETUNIFORMLOCATION, GetUniformLocation)                               \
  X(UNIFORMMATRIX4FV, UniformMatrix4fv)                                   \
  X(UNIFORM4FV, Uniform4fv)                                               \
  X(UNIFORM1I, Uniform1i)                                                 \
  X(GENFRAMEBUFFERS, GenFramebuffers)                                     \
  X(DELETEFRAMEBUFFERS, DeleteFramebuffers)                               \
  X(BINDFRAMEBUFFER, BindFramebuffer)                                     \
  X(GENRENDERBUFFERS, GenRenderbuffers)                                   \
  X(DELETERENDERBUFFERS, DeleteRenderbuffers)                             \
  X(BINDRENDERBUFFER, BindRenderbuffer)                                   \
  X(RENDERBUFFERSTORAGEMULTISAMPLE, RenderbufferStorageMultisample)       \
  X(FRAMEBUFFERRENDERBUFFER, FramebufferRenderbuffer)                     \
  X(CHECKFRAMEBUFFERSTATUS, CheckFramebufferStatus)                       \
  X(BLITFRAMEBUFFER, BlitFramebuffer)

struct GlFunctions {
#define FORESIGHT_GL_MEMBER(UPPER, Name) PFNGL##UPPER##PROC Name = nullptr;
  FORESIGHT_GL_FUNCTIONS(FORESIGHT_GL_MEMBER)
#undef FORESIGHT_GL_MEMBER

  /// Looks every function up; throws std::runtime_error naming a missing one.
  void load(const GlContext& context) {
#define FORESIGHT_GL_LOAD(UPPER, Name)                                                         \
  Name = reinterpret_cast<PFNGL##UPPER##PROC>(context.proc_address("gl" #Name));            \
  if (!Name)                                                                                   \
    throw std::runtime_error(std::string("GL function gl" #Name " not available from the ") + \
                             to_string(context.backend()) + " back end");
    FORESIGHT_GL_FUNCTIONS(FORESIGHT_GL_LOAD)
#undef FORESIGHT_GL_LOAD
  }
};

}  // namespace foresight::render::detail
