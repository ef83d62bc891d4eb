#pragma once
// Data beyond a memory bound, kept in an anonymous temporary file (std::tmpfile, removed when
// closed): written once during a run and read back by its reverse sweep (the adjoint
// checkpoints of FESD and time-stepping). Private to moreau::integrators.

#include <cstddef>
#include <cstdio>

namespace moreau::internal {

class SpillFile {
 public:
  SpillFile() = default;
  ~SpillFile();
  SpillFile(const SpillFile&) = delete;
  SpillFile& operator=(const SpillFile&) = delete;
  // Writes `count` doubles at byte `offset` (creating the file on first use) and returns the
  // offset after them. Throws std::runtime_error if the file cannot be created or written.
  long Write(long offset, const double* data, std::size_t count);
  // Reads `count` doubles written at byte `offset` into data. Throws std::runtime_error if they
  // cannot be read.
  void Read(long offset, double* data, std::size_t count);

 private:
  std::FILE* file_ = nullptr;
};

}  // namespace moreau::internal
