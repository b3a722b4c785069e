// The origin of a mesh read from coordinates more precise than floats (IndexedMesh::origin, far_origin): the
// PLY and OBJ readers hold their first vertices here, in double, until the origin is chosen from them.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "ocsimp/core/error.h"
#include "ocsimp/core/mesh.h"

namespace ocsimp::detail {

[[noreturn]] void fail_beyond_float_range(const std::string& path, FilePosition where, std::uint64_t number);

// `read` as float offsets from `origin`. Throws, naming vertex `number` at `where` of `path`, when a
// coordinate lies beyond float range from the origin. Inline: the readers call it for every vertex of a
// mesh far from zero.
inline Vec3f float_offset(const Vec3d& read, const Vec3d& origin, const std::string& path, FilePosition where,
                          std::uint64_t number) {
  const Vec3d offset = read - origin;
  if (!offset.allFinite() || offset.cwiseAbs().maxCoeff() > std::numeric_limits<float>::max())
    fail_beyond_float_range(path, where, number);
  return offset.cast<float>();
}

struct OriginSample {
  struct Held {
    Vec3d read;
    FilePosition where;
  };
  std::vector<Held> held;  // the first vertices, in file order
  bool settled = true;     // false while a reader of precise coordinates is still choosing

  bool full() const { return held.size() >= kOriginSample; }

  // Chooses the origin from the held vertices. They sit at the front of `positions`, as read rounded straight
  // to float; unless the origin is zero they are set again as offsets from it. Each is added to `bounds`.
  // Vertices are numbered from `first_number` in errors (0 for PLY, 1 for OBJ).
  Vec3d settle(const std::string& path, std::uint64_t first_number, std::vector<Vec3f>& positions,
               Box3& bounds);
};

}  // namespace ocsimp::detail
