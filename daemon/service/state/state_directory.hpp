#pragma once
// The state directory, checked and locked at start-up, before the device is touched: a missing
// or unsafe directory would otherwise be found only at the first checkpoint (a minute in, losing
// what was learned), and a second daemon on the same state would overwrite the first's.

#include <string>

namespace scp::daemon::state {

// Throws std::runtime_error naming the path and the remedy unless `directory` exists, is a
// directory (not a symlink to one), is owned by this user or root, and is writable by nobody
// else (a group- or world-writable directory lets another user plant a symlink or FIFO where
// the checkpoint goes).
void check_state_directory(const std::string& directory);

// An exclusive flock on DIRECTORY/scp-estimatord.lock, held for the life of the object: a second
// daemon on the same state directory is refused. Throws std::runtime_error naming the remedy.
class StateLock {
 public:
  // `holder` (e.g. "actuator bench-a, socket /run/...") is written into the lock file after this
  // process's pid, and a refused second daemon quotes what the holder wrote there.
  explicit StateLock(const std::string& directory, const std::string& holder = {});
  ~StateLock();
  StateLock(const StateLock&) = delete;
  StateLock& operator=(const StateLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace scp::daemon::state
