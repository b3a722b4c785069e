#include "ocsimp/streaming/mesh_stream.h"

#include <gtest/gtest.h>

#include "ocsimp/core/error.h"
#include "ocsimp/streaming/io.h"
#include "test_support.h"

namespace ocsimp {
namespace {

// A mesh handed in directly gets the check a reader gives its file: as a soup, a corner past the vertex
// array was read out of bounds (a segmentation fault for 0x7fffffff, garbage for one just past the end),
// and so were short attribute arrays.
TEST(MeshStream, IndicesPastTheArraysAreAnError) {
  IndexedMesh far_corner = test::grid_square(4);
  far_corner.triangles.push_back({0, 1, 25});
  IndexedMesh short_normals = test::grid_square(4);
  short_normals.normals.assign(20, Vec3f(0, 0, 1));
  for (bool as_soup : {false, true}) {
    EXPECT_THROW(make_mesh_stream(far_corner, as_soup), Error);
    EXPECT_THROW(make_mesh_stream(short_normals, as_soup), Error);
    const IndexedMesh good = test::grid_square(4);
    const IndexedMesh read = read_mesh(*make_mesh_stream(good, as_soup));
    EXPECT_EQ(read.face_count(), good.face_count());
  }
}

}  // namespace
}  // namespace ocsimp
