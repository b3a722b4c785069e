#include "origin_sample.h"

#include <limits>

namespace ocsimp::detail {

Vec3f float_offset(const Vec3d& read, const Vec3d& origin, const std::string& path, FilePosition where,
                   std::uint64_t number) {
  const Vec3d offset = read - origin;
  if (!offset.allFinite() || offset.cwiseAbs().maxCoeff() > std::numeric_limits<float>::max()) {
    throw Error(
        path, where,
        "vertex " + std::to_string(number) +
            " lies beyond the float range (+-3.4e38) from the other vertices, whose positions are held "
            "relative to their median");
  }
  return offset.cast<float>();
}

Vec3d OriginSample::settle(const std::string& path, std::uint64_t first_number, std::vector<Vec3f>& positions,
                           Box3& bounds) {
  std::vector<Vec3d> first(held.size());
  for (std::size_t i = 0; i < held.size(); ++i) first[i] = held[i].read;
  const Vec3d origin = far_origin(std::move(first));
  for (std::size_t i = 0; i < held.size(); ++i) {
    if (origin != Vec3d::Zero())
      positions[i] = float_offset(held[i].read, origin, path, held[i].where, first_number + i);
    bounds.add(positions[i]);
  }
  held = {};
  settled = true;
  return origin;
}

}  // namespace ocsimp::detail
