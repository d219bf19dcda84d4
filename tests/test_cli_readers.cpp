// The isotile program's OpenVDB and ITK readers, which it loads as modules on first use
// (core/volume/reader_modules.h): they read what the library reads, a run that reads neither
// format loads neither library, and a program without its modules says so in one line.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_support.h"
#include "core/extract/extract.h"
#include "core/volume/itk_reader.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"

namespace fs = std::filesystem;

namespace isotile {
namespace {

using testing::CliResult;

class CliReaders : public testing::CliTest {
 protected:
  // A sphere's samples in a float grid offset from the origin: the input the program must read
  // through its OpenVDB module.
  fs::path write_vdb() {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(1.0f);
    auto acc = grid->getAccessor();
    const Volume f = make_field_volume({FieldKind::Sphere, 20});
    for (int k = 0; k < 20; ++k)
      for (int j = 0; j < 20; ++j)
        for (int i = 0; i < 20; ++i)
          acc.setValueOn(openvdb::Coord(i + 3, j - 5, k + 7),
                         static_cast<float>(f.view().value(i, j, k)));
    const fs::path file = dir_ / "sphere.vdb";
    openvdb::io::File out(file.string());
    out.write({grid});
    out.close();
    return file;
  }

  // The same sphere as a MetaImage, for the ITK module.
  fs::path write_mha() {
    const Volume f = make_field_volume({FieldKind::Sphere, 20});
    const fs::path file = dir_ / "sphere.mha";
    write_itk(file.string(), f.bytes(), f.type(), f.dims(), {1, 1, 1}, {0, 0, 0}, kIdentity3);
    return file;
  }

  // The triangles of `input`'s Marching Cubes mesh at 0 as the library reads it.
  static std::uint64_t library_triangles(const fs::path& input) {
    ExtractOptions o;
    o.iso = 0;
    return extract(read_volume(input.string()).view(), o).triangles.size();
  }

  std::uint64_t program_triangles(const fs::path& input) {
    const CliResult r = run("-q extract '" + input.string() + "' --iso 0 -o out.ply --stats -");
    EXPECT_EQ(r.code, 0) << r.err;
    return r.code == 0 ? nlohmann::json::parse(r.out)["triangles"].get<std::uint64_t>() : 0;
  }
};

TEST_F(CliReaders, VdbThroughTheModuleAsInTheLibrary) {
  const fs::path vdb = write_vdb();
  const std::uint64_t want = library_triangles(vdb);
  ASSERT_GT(want, 100u);
  EXPECT_EQ(program_triangles(vdb), want);
}

TEST_F(CliReaders, ItkThroughTheModuleAsInTheLibrary) {
  if (!itk_available()) ISOTILE_SKIP(Itk, "built without ITK");
  const fs::path mha = write_mha();
  const std::uint64_t want = library_triangles(mha);
  ASSERT_GT(want, 100u);
  EXPECT_EQ(program_triangles(mha), want);
  // Errors raised inside the module reach the program's handler: one line, exit code 1.
  std::ofstream(dir_ / "bad.nii") << std::string(400, 'x');
  const CliResult r = run("-q extract bad.nii --iso 0 -o bad.ply");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("not a NIfTI file"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// A .vdb cut short anywhere, even by its last byte (which OpenVDB alone would not notice), is
// refused in one line, in core, out of core and by info, and leaves no output.
TEST_F(CliReaders, TruncatedVdbIsRefused) {
  const std::string bytes = testing::slurp(write_vdb());
  ASSERT_GT(bytes.size(), 1000u);
  for (const std::size_t keep :
       {bytes.size() - 1, bytes.size() * 3 / 4, bytes.size() / 2, std::size_t{200}}) {
    std::ofstream(dir_ / "cut.vdb", std::ios::binary) << bytes.substr(0, keep);
    for (const char* command :
         {"-q extract cut.vdb --iso 0 -o cut.ply",
          "-q extract cut.vdb --iso 0 -o cut.ply --memory 1MiB", "-q info cut.vdb"}) {
      fs::remove(dir_ / "cut.ply");
      const CliResult r = run(command);
      EXPECT_EQ(r.code, 1) << command << " at " << keep << " bytes: " << r.err;
      EXPECT_NE(r.err.find("cut.vdb"), std::string::npos) << r.err;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
      EXPECT_FALSE(fs::exists(dir_ / "cut.ply")) << command << " at " << keep;
    }
  }
}

// The dynamic loader's log of a run that reads a procedural field names neither library.
TEST_F(CliReaders, OtherInputsLoadNeitherLibrary) {
  const CliResult r = run("-q extract field:sphere:16 -o out.ply", "LD_DEBUG=libs");
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_NE(r.err.find("libtbb"), std::string::npos) << "LD_DEBUG gave no log";
  EXPECT_EQ(r.err.find("libopenvdb"), std::string::npos);
  EXPECT_EQ(r.err.find("libITK"), std::string::npos);
  EXPECT_EQ(r.err.find("libgdcm"), std::string::npos);
}

// A copy of the program away from its modules (a partial installation) reads other formats and
// refuses these two in one line that names the module and where it looked.
TEST_F(CliReaders, MissingModulesAreOneLineErrors) {
  const fs::path vdb = write_vdb();
  fs::create_directories(dir_ / "bin");
  fs::copy_file(ISOTILE_CLI, dir_ / "bin" / "isotile");
  auto run_copy = [&](const std::string& args) {
    const std::string cmd =
        "cd '" + dir_.string() + "' && ./bin/isotile " + args + " >out.txt 2>err.txt";
    const int status = std::system(cmd.c_str());
    CliResult r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.err = testing::slurp(dir_ / "err.txt");
    return r;
  };
  EXPECT_EQ(run_copy("-q extract field:sphere:16 -o field.ply").code, 0);
  const CliResult r = run_copy("-q extract sphere.vdb --iso 0 -o vdb.ply");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("libisotile_vdb_reader.so, which is not installed (looked in "),
            std::string::npos)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "vdb.ply"));
  if (itk_available()) {
    write_mha();
    const CliResult i = run_copy("-q extract sphere.mha --iso 0 -o mha.ply");
    EXPECT_EQ(i.code, 1);
    EXPECT_NE(i.err.find("libisotile_itk_reader.so"), std::string::npos) << i.err;
    EXPECT_FALSE(fs::exists(dir_ / "mha.ply"));
  }
}

}  // namespace
}  // namespace isotile
