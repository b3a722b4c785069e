#include "ocsimp/core/error.h"

namespace ocsimp {
namespace {

std::string format_message(const std::string& file, const FilePosition& position, const std::string& reason) {
  std::string message;
  if (!file.empty()) message += file + ": ";
  switch (position.kind) {
    case FilePosition::Kind::byte:
      message += "byte " + std::to_string(position.value) + ": ";
      break;
    case FilePosition::Kind::line:
      message += "line " + std::to_string(position.value) + ": ";
      break;
    case FilePosition::Kind::none:
      break;
  }
  message += reason;
  // Reasons quote the file's own bytes: a NUL would end the printed line early and an escape sequence
  // would drive the terminal, so control characters print as '?'.
  for (char& c : message) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return message;
}

}  // namespace

Error::Error(std::string file, FilePosition position, std::string reason)
    : std::runtime_error(format_message(file, position, reason)),
      file_(std::move(file)),
      position_(position),
      reason_(std::move(reason)) {}

}  // namespace ocsimp
