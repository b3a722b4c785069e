#include "ocsimp/streaming/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string_view>

#include "ocsimp/core/error.h"

namespace ocsimp {
namespace {

// Live temporaries, in fixed storage so the signal handler can unlink them without allocating.
constexpr int kMaxLive = 64;
constexpr std::size_t kMaxPath = 4096;
char g_live[kMaxLive][kMaxPath];
std::atomic<bool> g_used[kMaxLive];
std::mutex g_live_mutex;
std::once_flag g_handlers_installed;

// with_signals_deferred calls under way, and the signal they hold back (0: none).
std::atomic<int> g_deferring{0};
std::atomic<int> g_deferred_signal{0};

extern "C" void remove_temporaries_and_die(int signal_number) {
  if (g_deferring.load() > 0) {
    g_deferred_signal.store(signal_number);
    return;
  }
  for (int i = 0; i < kMaxLive; ++i) {
    if (g_used[i].load()) unlink(g_live[i]);
  }
  ::signal(signal_number, SIG_DFL);
  ::raise(signal_number);
}

void install_handlers() {
  for (int s : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction action {};
    action.sa_handler = remove_temporaries_and_die;
    sigemptyset(&action.sa_mask);
    sigaction(s, &action, nullptr);
  }
}

int register_live(const std::string& path) {
  std::call_once(g_handlers_installed, install_handlers);
  if (path.size() >= kMaxPath) return -1;
  std::lock_guard lock(g_live_mutex);
  for (int i = 0; i < kMaxLive; ++i) {
    if (!g_used[i].load()) {
      std::memcpy(g_live[i], path.c_str(), path.size() + 1);
      g_used[i].store(true);
      return i;
    }
  }
  return -1;
}

void unregister_live(const std::string& path) {
  std::lock_guard lock(g_live_mutex);
  for (int i = 0; i < kMaxLive; ++i) {
    if (g_used[i].load() && path == g_live[i]) g_used[i].store(false);
  }
}

std::string system_reason(std::string_view what) {
  return std::string(what) + ": " + std::strerror(errno);
}

// Where writing `path` lands: the file at the end of its chain of symbolic links (possibly not there yet, for
// a dangling link), so that the rename replaces that file and keeps the links, as writing through them
// would. Renaming over the link itself turned it into a regular file, and left its target stale.
std::filesystem::path link_target(const std::string& path) {
  namespace fs = std::filesystem;
  constexpr int kMaxLinks = 40;  // the kernel's own limit on a path's links
  fs::path at(path);
  for (int hops = 0; hops < kMaxLinks; ++hops) {
    std::error_code error;
    if (!fs::is_symlink(fs::symlink_status(at, error))) return at;
    const fs::path next = fs::read_symlink(at, error);
    if (error) throw Error(path, {}, "cannot read the symbolic link " + at.string() + ": " + error.message());
    at = next.is_absolute() ? next : at.parent_path() / next;
  }
  throw Error(path, {}, "too many levels of symbolic links");
}

// Whether `path` names something other than a regular file or a folder, that writing goes to directly: a
// device (/dev/null), a FIFO, /dev/stdout. A rename would replace it by a regular file: run as root,
// `-o /dev/null` made /dev/null a regular file for every process on the machine.
bool writes_directly(const std::string& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0 && !S_ISREG(info.st_mode) && !S_ISDIR(info.st_mode);
}

// An unnamed file in `folder` (O_TMPFILE), or -1 where the file system or kernel has none, or where the
// finished file could not be given a name through /proc/self/fd (see AtomicFile::commit). A process killed
// outright (SIGKILL, the kernel's out-of-memory killer) then leaves nothing behind, where a named temporary
// stayed in the output's folder: as large as the output got before the kill.
int open_unnamed(const std::string& folder) {
  const int fd = ::open(folder.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0600);
  if (fd < 0) return -1;
  struct stat info {};
  if (::stat(("/proc/self/fd/" + std::to_string(fd)).c_str(), &info) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// The longest file name the temporary's decoration leaves room for: a name a few bytes under the file
// system's limit of 255 (NAME_MAX) is valid, but its temporary was not.
constexpr std::size_t kTempDecoration = std::string_view(".").size() + std::string_view(".tmp.XXXXXX").size();
constexpr std::size_t kNameMax = 255;

// Links the unnamed file `fd` into its folder under a fresh name made from `pattern` (its Xs replaced), for
// the rename: linkat cannot replace an existing file, and rename needs a name to move. Registered at once,
// so that SIGINT, SIGTERM and SIGHUP remove it in the moment before the rename.
std::string give_name(int fd, const std::string& pattern, const std::string& path) {
  const std::string proc = "/proc/self/fd/" + std::to_string(fd);
  static std::atomic<unsigned> counter{0};
  const std::size_t x = pattern.rfind("XXXXXX");
  for (int attempt = 0; attempt < 1000; ++attempt) {
    std::string name = pattern;
    const unsigned long n = (static_cast<unsigned long>(::getpid()) << 16) ^ counter++ ^ (attempt * 7919ul);
    static constexpr char kDigits[] = "0123456789abcdefghijklmnopqrstuvwxyz";
    for (std::size_t i = 0; i < 6; ++i) name[x + i] = kDigits[(n >> (5 * i)) % 36];
    if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, name.c_str(), AT_SYMLINK_FOLLOW) == 0) {
      register_live(name);
      return name;
    }
    if (errno != EEXIST) break;
  }
  throw Error(path, {}, system_reason("cannot name the finished temporary file"));
}

// Names a finished file if it has no name yet, closes it and renames it over its target.
void publish_now(FinishedFile& file) {
  if (file.unnamed) {
    file.temp_path = give_name(file.fd, file.temp_path, file.path);
    file.unnamed = false;
  }
  const int fd = file.fd;
  file.fd = -1;
  if (::close(fd) != 0) throw Error(file.path, {}, system_reason("close failed"));
  if (std::rename(file.temp_path.c_str(), file.target_path.c_str()) != 0)
    throw Error(file.path, {}, system_reason("cannot rename the finished temporary into place"));
  unregister_live(file.temp_path);
  file.temp_path.clear();
}

void publish(FinishedFile& file) {
  with_signals_deferred([&] { publish_now(file); });  // no name left unregistered
}

// Deletes a finished file that was not published: an unnamed one is gone with its descriptor.
void discard(FinishedFile& file) {
  if (file.fd >= 0) ::close(file.fd);
  file.fd = -1;
  if (!file.unnamed && !file.temp_path.empty()) {
    ::unlink(file.temp_path.c_str());
    unregister_live(file.temp_path);
  }
  file.temp_path.clear();
}

// The files that commit() hands to the live HeldCommits, if any.
std::mutex g_held_mutex;
std::vector<FinishedFile>* g_held = nullptr;

}  // namespace

void check_writable(const std::string& path) {
  if (writes_directly(path)) {
    if (::access(path.c_str(), W_OK) != 0) throw Error(path, {}, system_reason("cannot write"));
    return;
  }
  AtomicFile probe(path);  // creates, then (uncommitted) deletes, a temporary beside the destination
}

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), buffer_(buffer_capacity) {
  if (writes_directly(path_)) {
    direct_ = true;
    target_path_ = path_;
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd_ < 0) throw Error(path_, {}, system_reason("cannot open for writing"));
    return;
  }
  target_path_ = link_target(path_).string();
  const std::filesystem::path target(target_path_);
  const std::filesystem::path folder = target.parent_path().empty() ? "." : target.parent_path();
  std::string temp_name(".");
  temp_name.append(target.filename().string().substr(0, kNameMax - kTempDecoration)).append(".tmp.XXXXXX");
  std::string pattern = (folder / temp_name).string();
  fd_ = open_unnamed(folder.string());
  if (fd_ >= 0) {
    unnamed_ = true;
    temp_path_ = pattern;  // the name commit() gives it, with its Xs replaced
    return;
  }
  fd_ = mkstemp(pattern.data());
  if (fd_ < 0) throw Error(path_, {}, system_reason("cannot create a temporary file in " + folder.string()));
  temp_path_ = pattern;
  register_live(temp_path_);
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    if (fd_ >= 0) ::close(fd_);
    if (direct_ || unnamed_) return;  // an unnamed file is gone with its descriptor
    ::unlink(temp_path_.c_str());
    unregister_live(temp_path_);
  }
}

void AtomicFile::check_open() const {
  if (committed_)
    throw Error(path_, {}, "the file is already complete (committed): nothing more can be written");
  if (fd_ < 0) throw Error(path_, {}, "the file was closed by an earlier failure");
}

char* AtomicFile::reserve(std::size_t size) {
  check_open();
  if (used_ + size > buffer_.size()) flush();
  return buffer_.data() + used_;
}

void AtomicFile::write(const void* data, std::size_t size) {
  check_open();
  const char* bytes = static_cast<const char*>(data);
  if (used_ + size > buffer_.size()) flush();
  if (size >= buffer_.size()) {
    // Large blocks bypass the buffer.
    while (size > 0) {
      const ssize_t n = ::write(fd_, bytes, size);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error(path_, {}, system_reason("write failed"));
      bytes += n;
      size -= static_cast<std::size_t>(n);
      flushed_ += static_cast<std::uint64_t>(n);
    }
    return;
  }
  std::memcpy(buffer_.data() + used_, bytes, size);
  used_ += size;
}

void AtomicFile::flush() {
  std::size_t done = 0;
  while (done < used_) {
    const ssize_t n = ::write(fd_, buffer_.data() + done, used_ - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(path_, {}, system_reason("write failed"));
    done += static_cast<std::size_t>(n);
  }
  flushed_ += used_;
  used_ = 0;
}

void AtomicFile::commit() {
  check_open();
  flush();
  if (direct_) {
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) throw Error(path_, {}, system_reason("close failed"));
    committed_ = true;
    return;
  }
  // A file replaced keeps its permissions (a private 0600 output stays private); a new one gets the usual
  // ones, where mkstemp made it 0600.
  struct stat existing {};
  if (::stat(target_path_.c_str(), &existing) == 0 && S_ISREG(existing.st_mode)) {
    ::fchmod(fd_, existing.st_mode & 07777);
  } else {
    const mode_t mask = ::umask(0);
    ::umask(mask);
    ::fchmod(fd_, 0666 & ~mask);
  }
  // The finished file is handed over: to a HeldCommits that makes it appear later, or made to appear now.
  FinishedFile finished{path_, target_path_, temp_path_, fd_, unnamed_};
  fd_ = -1;
  committed_ = true;
  {
    std::lock_guard lock(g_held_mutex);
    if (g_held) {
      g_held->push_back(std::move(finished));
      return;
    }
  }
  try {
    publish(finished);
  } catch (...) {
    discard(finished);
    throw;
  }
}

HeldCommits::HeldCommits() {
  std::lock_guard lock(g_held_mutex);
  if (g_held) throw Error("commits are already held");
  g_held = &files_;
}

HeldCommits::~HeldCommits() {
  {
    std::lock_guard lock(g_held_mutex);
    if (g_held == &files_) g_held = nullptr;
  }
  for (FinishedFile& file : files_) discard(file);
}

void with_signals_deferred(const std::function<void()>& work) {
  std::call_once(g_handlers_installed, install_handlers);
  ++g_deferring;
  struct Resume {
    ~Resume() {
      if (--g_deferring == 0) {
        if (const int signal_number = g_deferred_signal.exchange(0)) ::raise(signal_number);
      }
    }
  } resume;
  work();
}

void HeldCommits::release() {
  {
    std::lock_guard lock(g_held_mutex);
    g_held = nullptr;
  }
  std::size_t i = 0;
  try {
    with_signals_deferred([&] {  // all of them or none
      for (; i < files_.size(); ++i) publish(files_[i]);
    });
  } catch (...) {
    for (std::size_t j = i; j < files_.size(); ++j) discard(files_[j]);
    files_.clear();
    throw;
  }
  files_.clear();
}

}  // namespace ocsimp
