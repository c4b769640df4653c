// The CSV verdict log (~verdict_log), written on its own thread: the thread that verifies
// loops (inside loop_fusion: under its m_process lock) only appends a row to a queue and never
// waits for the file. A FIFO without a reader, a stalled reader, a full disk or a broken pipe
// therefore cost rows, never verification; every failure is reported with ROS_ERROR and
// counted.
//
// Rows are whole or absent: a write that fails part-way (a full disk) is cut back to where the
// row began (ftruncate), so the file never ends in a torn row and the rows lost are exactly the
// rows counted as failed. The header comes first: until it is written (a disk full when the log
// is opened) no row is written either (they are counted as failed), and it is written before
// the first row once there is space again.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <thread>

namespace rover_loop_fusion {

class VerdictLog {
 public:
  struct Stats {
    size_t appended = 0;  ///< rows handed to append()
    size_t written = 0;   ///< rows in the file
    size_t failed = 0;    ///< rows a write error lost (reported)
    size_t dropped = 0;   ///< rows dropped because max_queued rows were waiting (reported)
    size_t waiting = 0;   ///< rows queued, not yet written
  };

  /// write(2) or a stand-in with its contract (tests: a disk that fills up and frees again).
  typedef std::function<ssize_t(int fd, const void* data, size_t size)> WriteFunction;

  explicit VerdictLog(size_t max_queued = 100000);
  /// Waits up to 2 s for the queued rows, stops the writer (within ~0.2 s, whatever the file
  /// does) and reports with ROS_ERROR the rows that were not written.
  ~VerdictLog();
  VerdictLog(const VerdictLog&) = delete;
  VerdictLog& operator=(const VerdictLog&) = delete;

  /// Opens `path` for appending without blocking and starts the writer; `header` is written
  /// first if the file is new or empty, or not a regular file. False with *error if the file
  /// cannot be opened (no such directory, no permission, a directory). A FIFO without a reader
  /// is not an error: the writer opens it when a reader comes (logged); rows wait until then.
  bool open(const std::string& path, const std::string& header, std::string* error);
  bool isOpen() const { return static_cast<bool>(state_); }
  /// Replaces write(2) for the writer thread (a seam for tests, which cannot fill a disk
  /// everywhere). Call before open().
  void setWriteFunction(WriteFunction write);
  /// Queues one row (without newline). Never blocks, never throws.
  void append(const std::string& row) noexcept;
  /// Waits up to timeout_s for the queue to be written; returns the rows still waiting.
  size_t flush(double timeout_s);
  Stats stats() const;

 private:
  struct State;
  void writerLoop();
  std::unique_ptr<State> state_;
  std::thread writer_;
};

}  // namespace rover_loop_fusion
