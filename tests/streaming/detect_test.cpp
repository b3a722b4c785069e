#include <gtest/gtest.h>

#include <string>

#include "io_test_util.h"
#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

using test::TempDir;

const char* kAsciiPly =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
const char* kObj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
const char* kAsciiStl =
    "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"
    "endsolid t\n";

FileFormat detect_bytes(const TempDir& dir, const std::string& name, const std::string& bytes) {
  test::write_file_bytes(dir / name, bytes);
  return detect_format(dir / name);
}

TEST(Detect, PlyByMagicUnderAnyName) {
  TempDir dir;
  for (const char* name : {"m.dat", "m.obj", "m.stl", "m"}) {
    EXPECT_EQ(detect_bytes(dir, name, kAsciiPly), FileFormat::ply) << name;
  }
  std::string crlf = kAsciiPly;
  crlf.replace(0, 4, "ply\r\n");
  EXPECT_EQ(detect_bytes(dir, "crlf.bin", crlf), FileFormat::ply);
}

TEST(Detect, ObjByItsStatements) {
  TempDir dir;
  for (const char* name : {"m.dat", "m.txt", "m.stl", "m.ply", "m"}) {
    EXPECT_EQ(detect_bytes(dir, name, kObj), FileFormat::obj) << name;
  }
  EXPECT_EQ(detect_bytes(dir, "c.dat", "\n\n  # exported\nmtllib x.mtl\no thing\nv 0 0 0\n"),
            FileFormat::obj);
  EXPECT_EQ(detect_bytes(dir, "g.dat", "g group\nv 0 0 0\n"), FileFormat::obj);
  EXPECT_EQ(detect_bytes(dir, "t.dat", "v\t0 0 0\n"), FileFormat::obj);
  // And the whole read works from content alone.
  test::write_file_bytes(dir / "whole.dat", kObj);
  EXPECT_EQ(read_mesh(dir / "whole.dat").face_count(), 1u);
}

TEST(Detect, AsciiStlUnderAnyName) {
  TempDir dir;
  for (const char* name : {"m.dat", "m.txt", "m.obj", "m"}) {
    EXPECT_EQ(detect_bytes(dir, name, kAsciiStl), FileFormat::stl) << name;
  }
  EXPECT_EQ(detect_bytes(dir, "upper.dat", std::string("SOLID T\n") + (kAsciiStl + 8)), FileFormat::stl);
  test::write_file_bytes(dir / "whole.txt", kAsciiStl);
  EXPECT_EQ(read_mesh(dir / "whole.txt").face_count(), 1u);
}

TEST(Detect, BinaryStlWhoseHeaderSaysSolid) {
  TempDir dir;
  write_mesh(dir / "c.stl", test::cube(2));
  std::string bytes = test::read_file_bytes(dir / "c.stl");
  bytes.replace(0, 12, "solid binary");
  for (const char* name : {"c.dat", "c.obj", "c.stl", "c"}) {
    EXPECT_EQ(detect_bytes(dir, name, bytes), FileFormat::stl) << name;
  }
  EXPECT_EQ(read_mesh(dir / "c.dat").face_count(), test::cube(2).face_count());
}

// A binary STL's header is free text: one that began with another format's magic word was refused. Its
// exact size decides for a .stl; other names still go by the magic word.
TEST(Detect, BinaryStlWhoseHeaderStartsWithAnotherFormatsMagic) {
  TempDir dir;
  write_mesh(dir / "c.stl", test::cube(2));
  const std::string bytes = test::read_file_bytes(dir / "c.stl");
  for (const std::string& magic : {std::string("DRACO exporter"), std::string("ply\nexporter")}) {
    std::string edited = bytes;
    edited.replace(0, magic.size(), magic);
    EXPECT_EQ(detect_bytes(dir, "c.stl", edited), FileFormat::stl) << magic;
    EXPECT_EQ(read_mesh(dir / "c.stl").face_count(), test::cube(2).face_count()) << magic;
    EXPECT_NE(detect_bytes(dir, "c.dat", edited), FileFormat::stl) << magic;
  }
}

TEST(Detect, DracoByMagic) {
  TempDir dir;
  WriteOptions options;
  options.format = FileFormat::drc;
  write_mesh(dir / "s.bin", test::sphere(1), options);
  EXPECT_EQ(detect_format(dir / "s.bin"), FileFormat::drc);
  test::write_file_bytes(dir / "s.obj", test::read_file_bytes(dir / "s.bin"));
  EXPECT_EQ(detect_format(dir / "s.obj"), FileFormat::drc);
  EXPECT_EQ(read_mesh(dir / "s.obj").face_count(), test::sphere(1).face_count());
}

TEST(Detect, AmbiguousBinaryFallsBackOnTheExtension) {
  TempDir dir;
  // A binary STL whose count does not match its size: only the name can say what it was meant to be.
  std::string bytes(84 + 50, '\0');
  bytes[80] = 7;
  EXPECT_EQ(detect_bytes(dir, "broken.stl", bytes), FileFormat::stl);
  EXPECT_THROW(detect_bytes(dir, "broken.dat", bytes), Error);
}

TEST(Detect, UnrecognizedAndEmptyFilesAreErrors) {
  TempDir dir;
  try {
    detect_bytes(dir, "empty.dat", "");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), dir / "empty.dat");
    EXPECT_NE(e.reason().find("empty"), std::string::npos);
  }
  std::string noise;
  for (int i = 0; i < 300; ++i) noise.push_back(static_cast<char>((i * 37 + 11) & 0xFF));
  try {
    detect_bytes(dir, "noise.bin", noise);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), dir / "noise.bin");
    EXPECT_NE(e.reason().find("unrecognized"), std::string::npos) << e.what();
  }
  EXPECT_THROW(detect_format(dir / "missing.obj"), Error);
}

// What the pipeline plans for before it opens a file (opening a PLY reads all its vertices): the header's
// face count, bounded by what the data could hold; an OBJ's size over 40 bytes a face; 0 where nothing is
// announced or the file does not parse.
TEST(Detect, TrianglesHintComesFromTheHeaderAlone) {
  TempDir dir;
  const std::string ply = dir / "m.ply";
  test::write_file_bytes(ply, kAsciiPly);
  EXPECT_EQ(triangles_hint(ply), 1u);
  IndexedMesh quad;
  quad.positions = {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(1, 1, 0), Vec3f(0, 1, 0)};
  quad.triangles = {{0, 1, 2}, {0, 2, 3}};
  write_mesh(dir / "quad.ply", quad);
  EXPECT_EQ(triangles_hint(dir / "quad.ply"), 2u);
  // A header claiming 10^15 faces over 26 bytes of data plans for what those bytes could hold at the
  // shortest face line ("3 0 1 2\n").
  std::string claim = kAsciiPly;
  claim.replace(claim.find("element face 1"), 14, "element face 1000000000000000");
  test::write_file_bytes(dir / "claim.ply", claim);
  EXPECT_EQ(triangles_hint(dir / "claim.ply"), 26u / 8);
  std::string obj;
  for (int i = 0; i < 100; ++i) obj += kObj;
  test::write_file_bytes(dir / "m.obj", obj);
  EXPECT_EQ(triangles_hint(dir / "m.obj"), obj.size() / 40);
  test::write_file_bytes(dir / "m.stl", kAsciiStl);
  EXPECT_EQ(triangles_hint(dir / "m.stl"), 0u);
  std::string broken = kAsciiPly;
  broken.replace(broken.find("format ascii"), 12, "format bogus");
  test::write_file_bytes(dir / "broken.ply", broken);
  EXPECT_EQ(triangles_hint(dir / "broken.ply"), 0u);
  EXPECT_EQ(triangles_hint(dir / "missing.ply"), 0u);
}

TEST(Detect, OutputFormatFromExtension) {
  EXPECT_EQ(format_from_extension("a/b.OBJ"), FileFormat::obj);
  EXPECT_EQ(format_from_extension("x.Stl"), FileFormat::stl);
  EXPECT_EQ(format_from_extension("x.ply"), FileFormat::ply);
  EXPECT_EQ(format_from_extension("x.drc"), FileFormat::drc);
  EXPECT_THROW(format_from_extension("x.dat"), Error);
  EXPECT_THROW(format_from_extension("obj"), Error);
}

}  // namespace
}  // namespace ocsimp
