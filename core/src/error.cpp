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
  return message + reason;
}

}  // namespace

Error::Error(std::string file, FilePosition position, std::string reason)
    : std::runtime_error(format_message(file, position, reason)),
      file_(std::move(file)),
      position_(position),
      reason_(std::move(reason)) {}

}  // namespace ocsimp
