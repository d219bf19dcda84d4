/* Preloaded into `isotile` by tests/test_gl_cli.cpp and into python3 by tests/python
 * (LD_PRELOAD): counts the EGL contexts and initialised displays and the GL programs, buffers,
 * vertex arrays and framebuffers the process creates and deletes, and at the very end of the
 * process (this library's destructor runs after the program's and its libraries' exit handlers)
 * reports what is still alive. Exits 3 when anything is: the program left a GL or EGL object to
 * the drivers' exit handlers, which is what crashed NVIDIA's libEGL at exit (docs/gl.md). The GL
 * functions are counted through eglGetProcAddress, which is how the project's loader (glad) finds
 * them. */
#define _GNU_SOURCE
#include <EGL/egl.h>
#include <dlfcn.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

typedef unsigned int GLuint;
typedef int GLsizei;

static atomic_long contexts, contexts_made, displays, programs, programs_made, buffers, arrays,
    framebuffers;

/* The next definition in the global scope; where libEGL is not in it (loaded only as a dependency
 * of a module opened with RTLD_LOCAL, as Python opens extension modules), from libEGL itself. */
static void* real(const char* name) {
  void* f = dlsym(RTLD_NEXT, name);
  if (!f) {
    void* egl = dlopen("libEGL.so.1", RTLD_NOW | RTLD_NOLOAD);
    if (egl) f = dlsym(egl, name);
  }
  return f;
}

EGLContext eglCreateContext(EGLDisplay d, EGLConfig c, EGLContext share, const EGLint* attrs) {
  EGLContext (*f)(EGLDisplay, EGLConfig, EGLContext, const EGLint*) = real("eglCreateContext");
  EGLContext r = f(d, c, share, attrs);
  if (r != EGL_NO_CONTEXT) {
    ++contexts;
    ++contexts_made;
  }
  return r;
}

EGLBoolean eglDestroyContext(EGLDisplay d, EGLContext c) {
  EGLBoolean (*f)(EGLDisplay, EGLContext) = real("eglDestroyContext");
  EGLBoolean r = f(d, c);
  if (r) --contexts;
  return r;
}

/* Displays initialised and not terminated (a display initialised twice counts once). */
#define MAX_DISPLAYS 64
static EGLDisplay live[MAX_DISPLAYS];
static void track(EGLDisplay d, int on) {
  for (int i = 0; i < MAX_DISPLAYS; ++i)
    if (live[i] == d) {
      if (!on) {
        live[i] = 0;
        --displays;
      }
      return;
    }
  if (!on) return;
  for (int i = 0; i < MAX_DISPLAYS; ++i)
    if (!live[i]) {
      live[i] = d;
      ++displays;
      return;
    }
}

EGLBoolean eglInitialize(EGLDisplay d, EGLint* major, EGLint* minor) {
  EGLBoolean (*f)(EGLDisplay, EGLint*, EGLint*) = real("eglInitialize");
  EGLBoolean r = f(d, major, minor);
  if (r) track(d, 1);
  return r;
}

EGLBoolean eglTerminate(EGLDisplay d) {
  EGLBoolean (*f)(EGLDisplay) = real("eglTerminate");
  EGLBoolean r = f(d);
  if (r) track(d, 0);
  return r;
}

static GLuint (*real_create_program)(void);
static void (*real_delete_program)(GLuint);
static void (*real_create_buffers)(GLsizei, GLuint*);
static void (*real_delete_buffers)(GLsizei, const GLuint*);
static void (*real_create_arrays)(GLsizei, GLuint*);
static void (*real_delete_arrays)(GLsizei, const GLuint*);
static void (*real_create_framebuffers)(GLsizei, GLuint*);
static void (*real_delete_framebuffers)(GLsizei, const GLuint*);

static long named(GLsizei n, const GLuint* ids) {
  long k = 0;
  for (GLsizei i = 0; i < n; ++i) k += ids[i] != 0;
  return k;
}
static GLuint create_program(void) {
  GLuint p = real_create_program();
  if (p) {
    ++programs;
    ++programs_made;
  }
  return p;
}
static void delete_program(GLuint p) {
  if (p) --programs;
  real_delete_program(p);
}
static void create_buffers(GLsizei n, GLuint* ids) {
  real_create_buffers(n, ids);
  buffers += named(n, ids);
}
static void delete_buffers(GLsizei n, const GLuint* ids) {
  buffers -= named(n, ids);
  real_delete_buffers(n, ids);
}
static void create_arrays(GLsizei n, GLuint* ids) {
  real_create_arrays(n, ids);
  arrays += named(n, ids);
}
static void delete_arrays(GLsizei n, const GLuint* ids) {
  arrays -= named(n, ids);
  real_delete_arrays(n, ids);
}
static void create_framebuffers(GLsizei n, GLuint* ids) {
  real_create_framebuffers(n, ids);
  framebuffers += named(n, ids);
}
static void delete_framebuffers(GLsizei n, const GLuint* ids) {
  framebuffers -= named(n, ids);
  real_delete_framebuffers(n, ids);
}

typedef void (*Proc)(void);
Proc eglGetProcAddress(const char* name) {
  Proc (*f)(const char*) = real("eglGetProcAddress");
  Proc p = f(name);
  if (!p) return p;
#define WRAP(gl, store, wrapper)  \
  if (strcmp(name, gl) == 0) {    \
    store = (__typeof__(store))p; \
    return (Proc)wrapper;         \
  }
  WRAP("glCreateProgram", real_create_program, create_program)
  WRAP("glDeleteProgram", real_delete_program, delete_program)
  WRAP("glCreateBuffers", real_create_buffers, create_buffers)
  WRAP("glDeleteBuffers", real_delete_buffers, delete_buffers)
  WRAP("glCreateVertexArrays", real_create_arrays, create_arrays)
  WRAP("glDeleteVertexArrays", real_delete_arrays, delete_arrays)
  WRAP("glCreateFramebuffers", real_create_framebuffers, create_framebuffers)
  WRAP("glDeleteFramebuffers", real_delete_framebuffers, delete_framebuffers)
#undef WRAP
  return p;
}

__attribute__((destructor)) static void report(void) {
  const long left = contexts + displays + programs + buffers + arrays + framebuffers;
  fprintf(stderr,
          "gl_exit_check: %s at exit: %ld EGL contexts (of %ld made), %ld EGL displays, %ld "
          "programs (of %ld made), %ld buffers, %ld vertex arrays, %ld framebuffers\n",
          left ? "LEFT ALIVE" : "nothing alive", (long)contexts, (long)contexts_made,
          (long)displays, (long)programs, (long)programs_made, (long)buffers, (long)arrays,
          (long)framebuffers);
  fflush(stderr);
  if (left) _exit(3);
}
