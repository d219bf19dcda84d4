// The isotile program's subcommands, one file each (tiler/cli/*_command.cpp): each adds its
// options to the command line and runs from the parsed arguments. tiler/main.cpp only dispatches.
// The work is the library's (tiler/pipeline.h and core); these files parse and present.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <vector>

#include "tiler/cli/cli_common.h"

namespace isotile::cli {

// `isotile extract INPUT -o OUT [...]`: the library's pipeline (tiler/pipeline.h); under an MPI
// launcher with --memory, distributed (tiler/mpi_extract.h).
struct ExtractArgs {
  InputArgs in;
  std::string output;
  std::string iso;  // a number, "auto" or empty (a field's own)
  bool allow_empty = false;
  std::string method = "mc";
  std::string backend = "auto";
  std::string stats;
  bool normals = false;
  bool ascii = false;
  std::string dc_solver = "mass";
  std::string dc_hermite = "central";
  std::string dc_vertices = "patch";
  std::string quality = "fast";  // Macet
  double macet_relax = 0.0;
  bool quads = false;
  bool check_intersections = false;
  std::string memory;  // empty: in core
  std::string frame = "world";
  double simplify = 1;  // fraction of faces kept; 1: off
  std::string render;   // --render PICTURE.png: drawn from the written mesh
  // The method-specific options given on the command line (--quality, --dc-*, --quads): each
  // with another method is an error, not ignored.
  std::vector<std::string> given;
};

CLI::App* add_extract_command(CLI::App& app, ExtractArgs& args);
int run_extract(const ExtractArgs& args);

// `isotile info INPUT [--json]`: dims, type, frame, value range, histogram, --iso auto's choice.
struct InfoArgs {
  InputArgs in;
  bool json = false;
};
CLI::App* add_info_command(CLI::App& app, InfoArgs& args);
int run_info(const InfoArgs& args);

// `isotile quality MESH [--json]`: radius ratios, topology, intersections, distance to a reference.
struct QualityArgs {
  std::string path;
  bool json = false;
  bool check_intersections = false;
  std::string reference;
};
CLI::App* add_quality_command(CLI::App& app, QualityArgs& args);
int run_quality(const QualityArgs& args);

// `isotile simplify IN OUT --ratio R | --faces N | --max-error E`.
struct SimplifyArgs {
  std::string input, output, stats;
  double ratio = 0, max_error = 0, min_quality = 0.3;
  std::uint64_t faces = 0;
  bool no_relax = false, ascii = false;
};
CLI::App* add_simplify_command(CLI::App& app, SimplifyArgs& args);
int run_simplify(const SimplifyArgs& args);

// `isotile gl-info [--json]`: the OpenGL device and its limits.
CLI::App* add_gl_info_command(CLI::App& app, bool& json);
int run_gl_info(bool as_json);

}  // namespace isotile::cli
