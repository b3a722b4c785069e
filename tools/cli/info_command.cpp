// ocsimp info: counts, attributes, extent and connectivity defects of a mesh file.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "commands.h"
#include "ocsimp/core/mesh.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp::cli {

void add_info_command(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("info", "Print counts, attributes, bounding box and connectivity facts of a mesh");
  auto input = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  cmd->add_option("input", *input, "Mesh file (PLY, OBJ, STL or Draco; detected from content)")->required();
  cmd->add_flag("--json", *json, "Print one JSON object instead of text");
  cmd->callback([input, json] {
    const FileFormat format = detect_format(*input);
    // 108 bytes a face at peak on gen 4 M (the mesh and its sorted edges).
    check_whole_mesh_fits({*input}, 95, "info holds the whole mesh and its edges", "");
    ReadOptions read;
    read.faces_required = false;
    read.warn = make_console(true, *input).warn;
    const IndexedMesh mesh = read_mesh(*input, read);
    const MeshTopology topo = analyze_topology(mesh);
    // Faces of three distinct corners that still span no area (collinear or coincident positions, as a
    // coarse quantization leaves them): degenerate_faces counts repeated corner indices only.
    const auto zero_area =
        std::count_if(mesh.triangles.begin(), mesh.triangles.end(), [&](const Triangle& t) {
          if (has_repeated_corner(t)) return false;
          const Vec3d a = mesh.positions[t[0]].cast<double>();
          return (mesh.positions[t[1]].cast<double>() - a).cross(mesh.positions[t[2]].cast<double>() - a) ==
                 Vec3d::Zero();
        });
    Box3 box = mesh.bounds();  // in the file's coordinates
    box.lo += mesh.origin;
    box.hi += mesh.origin;
    nlohmann::json out;
    out["file"] = *input;
    out["format"] = format_name(format);
    out["vertices"] = mesh.vertex_count();
    out["faces"] = mesh.face_count();
    out["attributes"] = {
        {"normals", mesh.has_normals()}, {"colors", mesh.has_colors()}, {"uvs", mesh.has_uvs()}};
    out["bounding_box"] = {{"min", {box.lo.x(), box.lo.y(), box.lo.z()}},
                           {"max", {box.hi.x(), box.hi.y(), box.hi.z()}}};
    out["diagonal"] = box.diagonal();
    // Where the file's coordinates were taken from (IndexedMesh::origin): zero but for double coordinates
    // far from zero.
    out["origin"] = {mesh.origin.x(), mesh.origin.y(), mesh.origin.z()};
    out["edges"] = topo.edges;
    out["boundary_edges"] = topo.boundary_edges;
    out["non_manifold_edges"] = topo.non_manifold_edges;
    out["non_manifold_vertices"] = topo.non_manifold_vertices;
    out["inconsistently_oriented_edges"] = topo.inconsistent_edges;
    out["components"] = topo.components;
    out["degenerate_faces"] = topo.degenerate_faces;
    out["zero_area_faces"] = zero_area;
    out["duplicate_faces"] = topo.duplicate_faces;
    out["unreferenced_vertices"] = topo.unreferenced_vertices;
    if (*json) {
      std::printf("%s\n", json_text(out).c_str());
      return;
    }
    std::printf("%s (%s)\n", input->c_str(), format_name(format));
    std::printf("  vertices               %zu\n", mesh.vertex_count());
    std::printf("  faces                  %zu\n", mesh.face_count());
    std::printf("  attributes             %s%s%s%s\n", mesh.has_normals() ? "normals " : "",
                mesh.has_colors() ? "colors " : "", mesh.has_uvs() ? "uvs " : "",
                mesh.has_normals() || mesh.has_colors() || mesh.has_uvs() ? "" : "none");
    // Enough digits to tell the box's sides apart however far from zero it lies, up to what a double holds:
    // six, and one more for each decade its coordinates exceed its extent by (a float STL 2 wide at UTM
    // northings printed as "(499999, 4e+06, 98.963) .. (500001, 4e+06, 101.031)").
    if (box.empty()) {
      std::printf("  bounding box           none (no vertex)\n");  // as --json's null, not inf .. -inf
    } else {
      const double magnitude = std::max(box.lo.cwiseAbs().maxCoeff(), box.hi.cwiseAbs().maxCoeff());
      const double extent = box.extent().maxCoeff();
      const int digits = extent > 0 && magnitude > extent
                             ? std::min(17, 6 + static_cast<int>(std::floor(std::log10(magnitude / extent))))
                             : 6;
      std::printf("  bounding box           (%.*g, %.*g, %.*g) .. (%.*g, %.*g, %.*g)\n", digits, box.lo.x(),
                  digits, box.lo.y(), digits, box.lo.z(), digits, box.hi.x(), digits, box.hi.y(), digits,
                  box.hi.z());
    }
    if (mesh.origin != Vec3d::Zero()) {
      std::printf("  origin                 (%.17g, %.17g, %.17g): positions are held relative to it\n",
                  mesh.origin.x(), mesh.origin.y(), mesh.origin.z());
    }
    std::printf("  diagonal               %g\n", box.diagonal());
    std::printf("  edges                  %zu\n", topo.edges);
    std::printf("  boundary edges         %zu\n", topo.boundary_edges);
    std::printf("  non-manifold edges     %zu\n", topo.non_manifold_edges);
    std::printf("  non-manifold vertices  %zu\n", topo.non_manifold_vertices);
    std::printf("  misoriented edges      %zu\n", topo.inconsistent_edges);
    std::printf("  components             %zu\n", topo.components);
    std::printf("  degenerate faces       %zu (a repeated corner)\n", topo.degenerate_faces);
    std::printf("  zero-area faces        %td\n", zero_area);
    std::printf("  duplicate faces        %zu\n", topo.duplicate_faces);
    std::printf("  unreferenced vertices  %zu\n", topo.unreferenced_vertices);
  });
}

}  // namespace ocsimp::cli
