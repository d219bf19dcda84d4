// Linked GL programs saved on disk (glGetProgramBinary) and loaded by later runs
// (glProgramBinary), so that a process compiles only the programs no earlier run compiled.
//
// Folder: $XDG_CACHE_HOME/isotile, else $HOME/.cache/isotile. One file per program, named by a
// hash of its key: the device (GL vendor, renderer, version, GLSL version), every stage's full
// source as compiled (stage_source()), the transform-feedback varyings and this format's version.
// A file holds a header (magic, binary format, lengths, a 64-bit checksum), the key itself
// (compared whole, so a hash collision cannot load the wrong program) and the binary. It is
// written to a temporary file in the same folder and renamed over the entry, so several
// processes (or MPI ranks) writing the same entry at once leave one whole file. An entry that is
// short, long, fails its checksum or its key, or that the driver rejects (glProgramBinary raises
// an error or the program is not linked: a driver update) is compiled again and replaced, never
// used. A folder that cannot be made or written is not an error: one note on stderr, and the run
// goes on compiling. Drivers that cannot save programs (GL_NUM_PROGRAM_BINARY_FORMATS == 0: Mesa
// with its own shader cache off) compile every time. ISOTILE_PROGRAM_CACHE=off turns the cache
// off (measurements of cold runs). Call only inside a gl::Scope.
#pragma once

#include <glad/gl.h>

#include <filesystem>
#include <string>

namespace isotile::gl {

// Counts since the process started.
struct ProgramCacheCounts {
  int loaded = 0;    // programs taken from the cache
  int compiled = 0;  // programs compiled (cache missing, off, unsupported, or entry rejected)
  int rejected = 0;  // entries found but not used (corrupt, truncated, stale)
  // Wall seconds program() spent making programs: loading them from the cache, or compiling and
  // linking (and saving) them; the programs already made in this process cost nothing.
  double seconds = 0;
};
ProgramCacheCounts program_cache_counts();

// Whether this process can use the cache: the driver saves programs, the folder is known and
// the cache is not turned off. `why` gets the reason when not.
bool program_cache_enabled(std::string* why = nullptr);

// The folder ("" when neither XDG_CACHE_HOME nor HOME is set).
std::filesystem::path program_cache_dir();

// The key's entry file.
std::filesystem::path program_cache_file(const std::string& key);

// The program saved under `key` linked into a new program object, or 0 (nothing usable saved:
// the caller compiles it and calls store_program()).
GLuint load_program(const std::string& key);

// Saves the linked program `prog` under `key` (does nothing when the cache is not enabled).
void store_program(const std::string& key, GLuint prog);

// Counts a program compiled (program() calls it once per compilation).
void count_compiled_program();
// Adds the seconds program() spent making one program.
void count_program_seconds(double seconds);

}  // namespace isotile::gl
