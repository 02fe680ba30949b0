/* gl_api.h — every OpenGL function splatd calls, as one table of function pointers.
 *
 * libOSMesa and libOpenGL both export gl* symbols, so a direct call would reach the wrong
 * library for one of the two back ends. Instead the active back end's getproc
 * (eglGetProcAddress or OSMesaGetProcAddress) fills a gl_api, and code calls gl->Foo(...).
 *
 * To use a new GL function, append one line X(Name, PFNGLNAMEPROC) to GL_API_LIST (the name
 * without its "gl" prefix, and the PFN type from GL/glcorearb.h). Every entry is required:
 * gl_api_load fails, naming the function, when the back end does not provide it. */
#pragma once
#include <GL/glcorearb.h>

#include "sd_err.h"

#define GL_API_LIST(X)                                                        \
    /* state, errors, queries */                                              \
    X(GetError, PFNGLGETERRORPROC)                                            \
    X(GetString, PFNGLGETSTRINGPROC)                                          \
    X(GetStringi, PFNGLGETSTRINGIPROC)                                        \
    X(GetIntegerv, PFNGLGETINTEGERVPROC)                                      \
    X(GetIntegeri_v, PFNGLGETINTEGERI_VPROC)                                  \
    X(GetFloatv, PFNGLGETFLOATVPROC)                                          \
    X(Enable, PFNGLENABLEPROC)                                                \
    X(Disable, PFNGLDISABLEPROC)                                              \
    X(Enablei, PFNGLENABLEIPROC)                                              \
    X(Disablei, PFNGLDISABLEIPROC)                                            \
    X(Viewport, PFNGLVIEWPORTPROC)                                            \
    X(Scissor, PFNGLSCISSORPROC)                                              \
    X(Clear, PFNGLCLEARPROC)                                                  \
    X(ClearColor, PFNGLCLEARCOLORPROC)                                        \
    X(ClearDepth, PFNGLCLEARDEPTHPROC)                                        \
    X(ClearBufferfv, PFNGLCLEARBUFFERFVPROC)                                  \
    X(ClearBufferuiv, PFNGLCLEARBUFFERUIVPROC)                                \
    X(ClearBufferfi, PFNGLCLEARBUFFERFIPROC)                                  \
    X(DepthFunc, PFNGLDEPTHFUNCPROC)                                          \
    X(DepthMask, PFNGLDEPTHMASKPROC)                                          \
    X(DepthRange, PFNGLDEPTHRANGEPROC)                                        \
    X(ColorMask, PFNGLCOLORMASKPROC)                                          \
    X(ColorMaski, PFNGLCOLORMASKIPROC)                                        \
    X(BlendFunc, PFNGLBLENDFUNCPROC)                                          \
    X(BlendFunci, PFNGLBLENDFUNCIPROC)                                        \
    X(BlendFuncSeparate, PFNGLBLENDFUNCSEPARATEPROC)                          \
    X(BlendEquation, PFNGLBLENDEQUATIONPROC)                                  \
    X(PolygonOffset, PFNGLPOLYGONOFFSETPROC)                                  \
    X(PointParameteri, PFNGLPOINTPARAMETERIPROC)                              \
    X(PointSize, PFNGLPOINTSIZEPROC)                                          \
    X(Finish, PFNGLFINISHPROC)                                                \
    X(Flush, PFNGLFLUSHPROC)                                                  \
    X(PixelStorei, PFNGLPIXELSTOREIPROC)                                      \
    X(ReadBuffer, PFNGLREADBUFFERPROC)                                        \
    X(ReadPixels, PFNGLREADPIXELSPROC)                                        \
    X(DrawBuffer, PFNGLDRAWBUFFERPROC)                                        \
    X(DrawBuffers, PFNGLDRAWBUFFERSPROC)                                      \
    X(MemoryBarrier, PFNGLMEMORYBARRIERPROC)                                  \
    /* buffers */                                                             \
    X(GenBuffers, PFNGLGENBUFFERSPROC)                                        \
    X(DeleteBuffers, PFNGLDELETEBUFFERSPROC)                                  \
    X(BindBuffer, PFNGLBINDBUFFERPROC)                                        \
    X(BufferData, PFNGLBUFFERDATAPROC)                                        \
    X(BufferSubData, PFNGLBUFFERSUBDATAPROC)                                  \
    X(BufferStorage, PFNGLBUFFERSTORAGEPROC)                                  \
    X(BindBufferBase, PFNGLBINDBUFFERBASEPROC)                                \
    X(BindBufferRange, PFNGLBINDBUFFERRANGEPROC)                              \
    X(ClearBufferData, PFNGLCLEARBUFFERDATAPROC)                              \
    X(ClearBufferSubData, PFNGLCLEARBUFFERSUBDATAPROC)                        \
    X(CopyBufferSubData, PFNGLCOPYBUFFERSUBDATAPROC)                          \
    X(GetBufferSubData, PFNGLGETBUFFERSUBDATAPROC)                            \
    X(MapBufferRange, PFNGLMAPBUFFERRANGEPROC)                                \
    X(UnmapBuffer, PFNGLUNMAPBUFFERPROC)                                      \
    /* textures and images */                                                 \
    X(GenTextures, PFNGLGENTEXTURESPROC)                                      \
    X(DeleteTextures, PFNGLDELETETEXTURESPROC)                                \
    X(BindTexture, PFNGLBINDTEXTUREPROC)                                      \
    X(ActiveTexture, PFNGLACTIVETEXTUREPROC)                                  \
    X(TexImage2D, PFNGLTEXIMAGE2DPROC)                                        \
    X(TexStorage2D, PFNGLTEXSTORAGE2DPROC)                                    \
    X(TexSubImage2D, PFNGLTEXSUBIMAGE2DPROC)                                  \
    X(TexParameteri, PFNGLTEXPARAMETERIPROC)                                  \
    X(TexBuffer, PFNGLTEXBUFFERPROC)                                          \
    X(ClearTexImage, PFNGLCLEARTEXIMAGEPROC)                                  \
    X(BindImageTexture, PFNGLBINDIMAGETEXTUREPROC)                            \
    X(GetTexImage, PFNGLGETTEXIMAGEPROC)                                      \
    /* framebuffers */                                                        \
    X(GenFramebuffers, PFNGLGENFRAMEBUFFERSPROC)                              \
    X(DeleteFramebuffers, PFNGLDELETEFRAMEBUFFERSPROC)                        \
    X(BindFramebuffer, PFNGLBINDFRAMEBUFFERPROC)                              \
    X(FramebufferTexture2D, PFNGLFRAMEBUFFERTEXTURE2DPROC)                    \
    X(FramebufferRenderbuffer, PFNGLFRAMEBUFFERRENDERBUFFERPROC)              \
    X(CheckFramebufferStatus, PFNGLCHECKFRAMEBUFFERSTATUSPROC)                \
    X(GenRenderbuffers, PFNGLGENRENDERBUFFERSPROC)                            \
    X(DeleteRenderbuffers, PFNGLDELETERENDERBUFFERSPROC)                      \
    X(BindRenderbuffer, PFNGLBINDRENDERBUFFERPROC)                            \
    X(RenderbufferStorage, PFNGLRENDERBUFFERSTORAGEPROC)                      \
    X(BlitFramebuffer, PFNGLBLITFRAMEBUFFERPROC)                              \
    /* vertex arrays and drawing */                                           \
    X(GenVertexArrays, PFNGLGENVERTEXARRAYSPROC)                              \
    X(DeleteVertexArrays, PFNGLDELETEVERTEXARRAYSPROC)                        \
    X(BindVertexArray, PFNGLBINDVERTEXARRAYPROC)                              \
    X(VertexAttribPointer, PFNGLVERTEXATTRIBPOINTERPROC)                      \
    X(VertexAttribIPointer, PFNGLVERTEXATTRIBIPOINTERPROC)                    \
    X(EnableVertexAttribArray, PFNGLENABLEVERTEXATTRIBARRAYPROC)              \
    X(DisableVertexAttribArray, PFNGLDISABLEVERTEXATTRIBARRAYPROC)            \
    X(VertexAttribDivisor, PFNGLVERTEXATTRIBDIVISORPROC)                      \
    X(DrawArrays, PFNGLDRAWARRAYSPROC)                                        \
    X(DrawArraysInstanced, PFNGLDRAWARRAYSINSTANCEDPROC)                      \
    X(MultiDrawArrays, PFNGLMULTIDRAWARRAYSPROC)                              \
    X(DrawElements, PFNGLDRAWELEMENTSPROC)                                    \
    /* shaders and programs */                                                \
    X(CreateShader, PFNGLCREATESHADERPROC)                                    \
    X(ShaderSource, PFNGLSHADERSOURCEPROC)                                    \
    X(CompileShader, PFNGLCOMPILESHADERPROC)                                  \
    X(GetShaderiv, PFNGLGETSHADERIVPROC)                                      \
    X(GetShaderInfoLog, PFNGLGETSHADERINFOLOGPROC)                            \
    X(DeleteShader, PFNGLDELETESHADERPROC)                                    \
    X(CreateProgram, PFNGLCREATEPROGRAMPROC)                                  \
    X(AttachShader, PFNGLATTACHSHADERPROC)                                    \
    X(DetachShader, PFNGLDETACHSHADERPROC)                                    \
    X(LinkProgram, PFNGLLINKPROGRAMPROC)                                      \
    X(GetProgramiv, PFNGLGETPROGRAMIVPROC)                                    \
    X(GetProgramInfoLog, PFNGLGETPROGRAMINFOLOGPROC)                          \
    X(DeleteProgram, PFNGLDELETEPROGRAMPROC)                                  \
    X(UseProgram, PFNGLUSEPROGRAMPROC)                                        \
    X(GetUniformLocation, PFNGLGETUNIFORMLOCATIONPROC)                        \
    X(Uniform1i, PFNGLUNIFORM1IPROC)                                          \
    X(Uniform2i, PFNGLUNIFORM2IPROC)                                          \
    X(Uniform1ui, PFNGLUNIFORM1UIPROC)                                        \
    X(Uniform2ui, PFNGLUNIFORM2UIPROC)                                        \
    X(Uniform1f, PFNGLUNIFORM1FPROC)                                          \
    X(Uniform2f, PFNGLUNIFORM2FPROC)                                          \
    X(Uniform3f, PFNGLUNIFORM3FPROC)                                          \
    X(Uniform4f, PFNGLUNIFORM4FPROC)                                          \
    X(Uniform1fv, PFNGLUNIFORM1FVPROC)                                        \
    X(Uniform3fv, PFNGLUNIFORM3FVPROC)                                        \
    X(Uniform4fv, PFNGLUNIFORM4FVPROC)                                        \
    X(UniformMatrix3fv, PFNGLUNIFORMMATRIX3FVPROC)                            \
    X(UniformMatrix4fv, PFNGLUNIFORMMATRIX4FVPROC)                            \
    /* compute */                                                             \
    X(DispatchCompute, PFNGLDISPATCHCOMPUTEPROC)                              \
    X(DispatchComputeIndirect, PFNGLDISPATCHCOMPUTEINDIRECTPROC)              \
    /* timer queries */                                                       \
    X(GenQueries, PFNGLGENQUERIESPROC)                                        \
    X(DeleteQueries, PFNGLDELETEQUERIESPROC)                                  \
    X(BeginQuery, PFNGLBEGINQUERYPROC)                                        \
    X(EndQuery, PFNGLENDQUERYPROC)                                            \
    X(GetQueryObjectui64v, PFNGLGETQUERYOBJECTUI64VPROC)

typedef struct gl_api {
#define GL_API_FIELD_(name, type) type name;
    GL_API_LIST(GL_API_FIELD_)
#undef GL_API_FIELD_
} gl_api;

/* The back end's lookup: returns the address of the GL function `name` ("glGenBuffers"), or
 * NULL. user is passed through. */
typedef void *(*gl_getproc_fn)(void *user, const char *name);

/* gl_api_load: fills every entry of gl through getproc (the context must be current).
 * Returns 0, or SD_EGL naming the first function the back end lacks; gl is zeroed then. */
int gl_api_load(gl_api *gl, gl_getproc_fn getproc, void *user, sd_err *err);

/* gl_check: reads and clears every pending GL error. Returns 0 when there was none, else
 * SD_EGL with err naming the errors ("GL_INVALID_OPERATION") and where (`what`). Call it after
 * setup (programs, buffers, framebuffers) always, and after each pass through GL_CHECK_PASS. */
int gl_check(const gl_api *gl, const char *what, sd_err *err);

/* GL_CHECK_PASS: gl_check in debug builds (no NDEBUG), nothing in release builds, since
 * glGetError waits for the GL pipeline on some drivers. Evaluates to 0 or SD_EGL. */
#ifdef NDEBUG
#define GL_CHECK_PASS(gl, what, err) 0
#else
#define GL_CHECK_PASS(gl, what, err) gl_check((gl), (what), (err))
#endif
