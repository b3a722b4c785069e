#include "ocsimp/streaming/mesh_stream.h"

#include <algorithm>
#include <array>

namespace ocsimp {
namespace {

class MeshStream final : public TriangleStream {
 public:
  MeshStream(IndexedMesh mesh, bool as_soup, std::size_t capacity)
      : triangles_(std::move(mesh.triangles)),
        as_soup_(as_soup),
        capacity_(std::max<std::size_t>(capacity, 1)) {
    mesh.triangles.clear();
    bounds_ = mesh.bounds();
    if (as_soup_) {
      soup_ = std::move(mesh);  // its attributes ride on the corners
      vertices_.origin = soup_.origin;
    } else {
      vertices_ = std::move(mesh);
    }
  }

  bool next(TriangleBatch& batch) override {
    batch.clear();
    const std::size_t end = std::min(triangles_.size(), cursor_ + capacity_);
    for (; cursor_ < end; ++cursor_) {
      const Triangle& t = triangles_[cursor_];
      if (as_soup_) {
        batch.corners.push_back(corners_of(soup_.positions, t));
        if (soup_.has_normals()) batch.corner_normals.push_back(corners_of(soup_.normals, t));
        if (soup_.has_colors()) batch.corner_colors.push_back(corners_of(soup_.colors, t));
        if (soup_.has_uvs()) batch.corner_uvs.push_back(corners_of(soup_.uvs, t));
      } else {
        batch.triangles.push_back(t);
      }
    }
    return batch.size() > 0;
  }
  const IndexedMesh& vertices() const override { return vertices_; }
  Box3 bounds() override { return bounds_; }
  std::uint64_t triangles_hint() const override { return triangles_.size(); }
  std::uint64_t bytes_read() const override { return cursor_ * sizeof(Triangle); }
  std::uint64_t bytes_total() const override { return triangles_.size() * sizeof(Triangle); }
  const std::string& path() const override { return path_; }

 private:
  template <class T>
  static std::array<T, 3> corners_of(const std::vector<T>& values, const Triangle& t) {
    return {values[t[0]], values[t[1]], values[t[2]]};
  }

  IndexedMesh vertices_;
  IndexedMesh soup_;  // as a soup: the vertices, without triangles
  std::vector<Triangle> triangles_;
  bool as_soup_;
  std::size_t capacity_;
  std::size_t cursor_ = 0;
  Box3 bounds_;
  std::string path_ = "<memory>";
};

}  // namespace

std::unique_ptr<TriangleStream> make_mesh_stream(IndexedMesh mesh, bool as_soup, std::size_t batch_capacity) {
  // Every reader checks its file's indices; the stream's consumers index the arrays without checking.
  check_indices(mesh, "in-memory mesh: ");
  return std::make_unique<MeshStream>(std::move(mesh), as_soup, batch_capacity);
}

}  // namespace ocsimp
