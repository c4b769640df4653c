#include "rover_loop_fusion/ros/verdict_log.h"

#include "rover_loop_fusion/ros/guarded.h"

#include <ros/console.h>

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>

namespace rover_loop_fusion {

namespace {

constexpr int kPollMs = 200;  // how soon the writer notices a stop or a reader of a FIFO

/// Never blocks: a FIFO without a reader fails with ENXIO instead of waiting for one.
int openNonBlocking(const std::string& path) {
  return ::open(path.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC | O_NONBLOCK, 0644);
}

/// Writes all of data to the non-blocking fd, waiting (in kPollMs steps) while the reader of a
/// pipe is not reading. 0, or the errno of the failure (ECANCELED when `stop` was set).
int writeAll(int fd, const std::string& data, const std::atomic<bool>& stop, const VerdictLog::WriteFunction& write) {
  size_t off = 0;
  while (off < data.size()) {
    errno = 0;
    const ssize_t w = write(fd, data.data() + off, data.size() - off);
    if (w > 0) {
      off += static_cast<size_t>(w);
      continue;
    }
    if (w < 0 && errno == EINTR) continue;
    if (w < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
      if (stop) return ECANCELED;
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, kPollMs);
      continue;
    }
    return w < 0 ? errno : EIO;
  }
  return 0;
}

}  // namespace

struct VerdictLog::State {
  std::mutex mutex;
  std::condition_variable wake;     // rows queued, or stop
  std::condition_variable drained;  // nothing waiting
  std::deque<std::string> queue;
  size_t in_flight = 0;  // rows the writer took from the queue and has not finished
  std::atomic<bool> stop{false};
  std::string path;
  std::string header;
  bool header_pending = false;
  bool header_tried = false;  // written (or tried) before any row was queued
  bool regular_file = false;
  int fd = -1;            // -1: FIFO waiting for a reader, or open failed
  bool open_failed = false;
  size_t max_queued = 0;
  Stats stats;
  WriteFunction write = [](int fd, const void* data, size_t size) { return ::write(fd, data, size); };
  // A failed write of a regular file that could not be cut back: the file ends in a partial
  // record, and the next one starts on a new line (writer thread only).
  bool torn = false;

  /// Writes one record (the header or a row) whole or not at all: in a regular file a write
  /// that fails part-way is cut back to where the record began. 0 or the errno of the failure.
  int writeRecord(int fd, const std::string& data);
  /// With the mutex held: opens the file if it is not open (a FIFO: once a reader came).
  void tryOpen();
  /// Without the mutex: the header (if `header`) and then the rows of a batch to fd; the
  /// errno of the last failure (0: none), and *header_written, *written, *failed.
  int writeBatch(int fd, bool header, const std::deque<std::string>& batch, bool* header_written, size_t* written,
                 size_t* failed);
};

void VerdictLog::State::tryOpen() {
  if (fd >= 0 || open_failed) return;
  const int opened = openNonBlocking(path);
  const int err = errno;
  if (opened >= 0) {
    fd = opened;
    header_tried = false;
    ROS_INFO("[rover] verdict log %s: a reader opened it, writing", path.c_str());
  } else if (err != ENXIO) {
    open_failed = true;
    ROS_ERROR("[rover] verdict log %s cannot be opened (%s): verdict rows are lost from now on", path.c_str(),
              std::strerror(err));
  }
}

int VerdictLog::State::writeBatch(int to, bool header, const std::deque<std::string>& batch, bool* header_written,
                                  size_t* written, size_t* failed) {
  int err = 0;
  // No row without the header before it: if it cannot be written (a full disk), the batch is
  // lost and the header is tried again before the next one.
  *header_written = to >= 0 && header && (err = writeRecord(to, this->header)) == 0;
  for (const std::string& row : batch) {
    if (to < 0 || (header && !*header_written) || err == EPIPE || err == ECANCELED) {
      ++*failed;  // open failed, no header, the reader went away, or shutting down
      continue;
    }
    const int e = writeRecord(to, row);
    if (e == 0) {
      ++*written;
    } else {
      ++*failed;
      err = e;
    }
  }
  return err;
}

int VerdictLog::State::writeRecord(int fd, const std::string& data) {
  const off_t start = regular_file ? ::lseek(fd, 0, SEEK_END) : static_cast<off_t>(-1);
  const int err = torn ? writeAll(fd, "\n" + data, stop, write) : writeAll(fd, data, stop, write);
  if (err == 0) {
    torn = false;
    return 0;
  }
  if (start >= 0) {
    struct stat st;
    if (::fstat(fd, &st) == 0 && st.st_size > start && ::ftruncate(fd, start) != 0) {
      torn = true;
      ROS_ERROR("[rover] verdict log %s: a write failed part-way and the partial row cannot be removed (%s): the "
                "file ends in a partial row at byte %lld; the next row starts on a new line",
                path.c_str(), std::strerror(errno), static_cast<long long>(start));
    }
  }
  return err;
}

VerdictLog::VerdictLog(size_t max_queued) : state_(new State) { state_->max_queued = max_queued; }

void VerdictLog::setWriteFunction(WriteFunction write) {
  if (!writer_.joinable() && write) state_->write = std::move(write);
}

VerdictLog::~VerdictLog() {
  if (!writer_.joinable()) return;
  flush(2.0);
  {
    std::lock_guard<std::mutex> lock(state_->mutex);
    state_->stop = true;
  }
  state_->wake.notify_all();
  writer_.join();
  const Stats s = stats();
  const size_t lost = s.waiting + s.failed + s.dropped;
  if (lost > 0)
    ROS_ERROR("[rover] verdict log %s: %zu of %zu verdict rows were not written (%zu write errors, %zu dropped "
              "from a full queue, %zu still waiting at shutdown)",
              state_->path.c_str(), lost, s.appended, s.failed, s.dropped, s.waiting);
  if (state_->fd >= 0) ::close(state_->fd);
}

bool VerdictLog::open(const std::string& path, const std::string& header, std::string* error) {
  State& s = *state_;
  s.path = path;
  s.header = header + "\n";
  const int fd = openNonBlocking(path);
  if (fd < 0 && errno != ENXIO) {
    if (error) *error = "cannot open verdict log " + path + ": " + std::strerror(errno);
    return false;
  }
  s.fd = fd;
  struct stat st;
  if (fd >= 0 && ::fstat(fd, &st) == 0) {
    s.regular_file = S_ISREG(st.st_mode);
    s.header_pending = !s.regular_file || st.st_size == 0;
  } else {
    s.header_pending = true;  // a FIFO without a reader yet
    ROS_WARN("[rover] verdict log %s has no reader yet (a FIFO?): verdict rows wait in memory (up to %zu) "
             "until one opens it",
             path.c_str(), s.max_queued);
  }
  writer_ = std::thread(&VerdictLog::writerLoop, this);
  return true;
}

void VerdictLog::append(const std::string& row) noexcept {
  if (!state_ || !writer_.joinable()) return;
  State& s = *state_;
  guarded("verdict log: queueing a row", [&] {
    {
      std::lock_guard<std::mutex> lock(s.mutex);
      ++s.stats.appended;
      if (s.queue.size() >= s.max_queued) {
        ++s.stats.dropped;
        ROS_ERROR_THROTTLE(5.0, "[rover] verdict log %s: %zu rows are waiting to be written; row dropped (%zu so far)",
                           s.path.c_str(), s.queue.size(), s.stats.dropped);
        return;
      }
      s.queue.push_back(row + "\n");
    }
    s.wake.notify_one();
  });
}

size_t VerdictLog::flush(double timeout_s) {
  State& s = *state_;
  std::unique_lock<std::mutex> lock(s.mutex);
  if (writer_.joinable())
    s.drained.wait_for(lock, std::chrono::duration<double>(timeout_s),
                       [&] { return s.queue.empty() && s.in_flight == 0; });
  return s.queue.size() + s.in_flight;
}

VerdictLog::Stats VerdictLog::stats() const {
  std::lock_guard<std::mutex> lock(state_->mutex);
  Stats out = state_->stats;
  out.waiting = state_->queue.size() + state_->in_flight;
  return out;
}

void VerdictLog::writerLoop() {
  // A reader that goes away must give EPIPE, not SIGPIPE (roscpp ignores SIGPIPE; a host might not).
  sigset_t pipe;
  sigemptyset(&pipe);
  sigaddset(&pipe, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &pipe, nullptr);

  State& s = *state_;
  std::unique_lock<std::mutex> lock(s.mutex);
  while (true) {
    s.tryOpen();
    const bool waiting_for_reader = s.fd < 0 && !s.open_failed;
    if (s.queue.empty() && s.header_pending && s.fd >= 0 && !s.header_tried) {
      // The header as soon as the file is open, so that a log of a run without verdicts is a
      // CSV file with its header, not an empty file. Tried once here; if it fails (a full disk),
      // again before each batch, as below.
      s.header_tried = true;
      const int fd = s.fd;
      lock.unlock();
      const int err = s.writeRecord(fd, s.header);
      lock.lock();
      if (err == 0) s.header_pending = false;
      continue;
    }
    if (s.queue.empty() || waiting_for_reader) {
      if (s.queue.empty()) s.drained.notify_all();
      if (s.stop) return;
      s.wake.wait_for(lock, std::chrono::milliseconds(kPollMs));
      continue;
    }
    std::deque<std::string> batch;
    batch.swap(s.queue);
    s.in_flight = batch.size();
    const int fd = s.fd;
    const bool header = s.header_pending;
    lock.unlock();

    bool header_written = false;
    size_t written = 0, failed = 0;
    const int err = s.writeBatch(fd, header, batch, &header_written, &written, &failed);

    lock.lock();
    if (header_written) s.header_pending = false;
    s.in_flight = 0;
    s.stats.written += written;
    if (err == ECANCELED) {
      s.in_flight = failed;  // stopped: the destructor reports them as not written
      return;
    }
    s.stats.failed += failed;
    if (failed > 0 && fd >= 0)
      ROS_ERROR_THROTTLE(5.0, "[rover] verdict log %s: write failed (%s)%s; %zu verdict rows lost so far (rows are "
                         "whole or absent)",
                         s.path.c_str(), std::strerror(err),
                         header && !header_written ? ", the header too: no row is written before it" : "",
                         s.stats.failed);
    if (err == EPIPE) {
      // The reader of a FIFO went away: wait for the next one.
      ::close(s.fd);
      s.fd = -1;
      s.header_pending = true;
    }
  }
}

}  // namespace rover_loop_fusion
