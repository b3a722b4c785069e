// ocsimp convert: any supported format to any other, chosen by the output extension.
#include "commands.h"
#include "ocsimp/streaming/io.h"

namespace ocsimp::cli {

void add_convert_command(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("convert", "Convert a mesh between PLY, OBJ, STL and Draco (by output extension)");
  struct Flags {
    std::string input, output;
    WriteOptions write;
    bool quiet = false;
  };
  auto flags = std::make_shared<Flags>();
  cmd->add_option("input", flags->input, "Input mesh (format detected from content)")->required();
  // Also as -o, the spelling every other command that writes a mesh takes.
  cmd->add_option("output,-o,--output", flags->output,
                  "Output mesh (.ply, .obj, .stl or .drc), given either after the input or after -o")
      ->check(file_name())
      ->required();
  cmd->add_flag("--ascii", flags->write.ascii, "Text PLY or STL instead of binary");
  cmd->add_option("--draco-bits", flags->write.draco_position_bits, "Draco position quantization bits")
      ->capture_default_str()
      ->transform(whole_number(1, kMaxDracoPositionBits));
  cmd->add_option("--draco-level", flags->write.draco_compression_level, "Draco compression level (0..10)")
      ->capture_default_str()
      ->transform(whole_number(0, 10));
  cmd->add_flag("-q,--quiet", flags->quiet, "No progress bar");
  cmd->callback([flags] {
    const FileFormat to =
        check_mesh_destination(flags->output, flags->input);  // refuse a bad destination first
    // At peak on gen 4 M: 20 bytes a face to PLY, OBJ or STL, 113 to Draco (its encoder's tables).
    check_whole_mesh_fits({flags->input}, to == FileFormat::drc ? 100 : 16, "convert holds the whole mesh",
                          "");
    const Console console = make_console(flags->quiet, flags->input);
    ReadOptions read;
    read.progress = console.progress;
    read.warn = console.warn;
    read.faces_required = false;  // a mesh without faces converts too, with write_result's warning
    // Every corner keeps its own uv and normal: a seam's sides become vertices of their own at one position,
    // which an OBJ output joins again in its `v` lines (an OBJ converts to an OBJ unchanged but for
    // numbering) and PLY and Draco outputs keep as separate vertices, as glTF-style files do.
    read.split_corner_attributes = true;
    // A copy: stored in the flags, which outlive the command, the bar's last owner kept its line open
    // until after main printed an error, which then ran on after the bar.
    WriteOptions write = flags->write;
    write.progress = read.progress;
    write_result(flags->output, read_mesh(flags->input, read), write);
  });
}

}  // namespace ocsimp::cli
