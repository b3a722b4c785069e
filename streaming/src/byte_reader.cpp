#include "byte_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "ocsimp/core/error.h"

namespace ocsimp::detail {

ByteReader::ByteReader(std::string path, std::size_t capacity) : path_(std::move(path)) {
  // An error names its file first, and an empty name would leave the message naming nothing.
  if (path_.empty()) throw Error("cannot open '': an empty file name");
  // Without O_NONBLOCK, opening a FIFO that no process writes waits for one forever, before the check below
  // could refuse it. A regular file's reads ignore the flag.
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd_ < 0) throw Error(path_, {}, std::string("cannot open: ") + std::strerror(errno));
  struct stat info {};
  if (::fstat(fd_, &info) != 0 || !S_ISREG(info.st_mode)) {
    ::close(fd_);
    throw Error(path_, {}, "not a regular file");
  }
  file_size_ = static_cast<std::uint64_t>(info.st_size);
  // A small file needs no large buffer: with room for the whole file plus one byte every fill() behaves as
  // with the full capacity, and opening many small files (tests, fuzzing) stops costing 4 MiB each.
  const std::uint64_t enough = std::max<std::uint64_t>(file_size_ + 1, 64 << 10);
  buffer_.resize(static_cast<std::size_t>(std::min<std::uint64_t>(capacity, enough)));
  ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
}

ByteReader::~ByteReader() {
  if (fd_ >= 0) ::close(fd_);
}

std::size_t ByteReader::fill(std::size_t count) {
  if (available() >= count || eof_) return available();
  // Move the unread tail to the front, then read until `count` bytes are there or the file ends.
  const std::size_t tail = end_ - cursor_;
  if (cursor_ > 0) {
    std::memmove(buffer_.data(), buffer_.data() + cursor_, tail);
    window_offset_ += cursor_;
    cursor_ = 0;
    end_ = tail;
  }
  // A record larger than the window (a vertex of a hundred thousand properties) grows it, but only to what
  // the file still holds: a header's claim alone allocates nothing, and a record the file cuts short is
  // reported as such by the caller.
  if (count > buffer_.size() && count <= file_size_ - std::min(file_size_, window_offset_))
    buffer_.resize(count);
  // The window is filled whole: read_at returns less only where the file ends.
  const std::size_t room = buffer_.size() - end_;
  const std::size_t n = read_at(window_offset_ + end_, buffer_.data() + end_, room);
  end_ += n;
  if (n < room) eof_ = true;
  return available();
}

void ByteReader::seek(std::uint64_t offset) {
  window_offset_ = offset;
  cursor_ = end_ = 0;
  eof_ = false;
}

std::size_t ByteReader::read_at(std::uint64_t offset, char* out, std::size_t count) const {
  std::size_t done = 0;
  while (done < count) {
    const ssize_t n = ::pread(fd_, out + done, count - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      throw Error(path_, FilePosition::byte(offset + done),
                  std::string("read failed: ") + std::strerror(errno));
    }
    if (n == 0) break;
    done += static_cast<std::size_t>(n);
  }
  return done;
}

}  // namespace ocsimp::detail
