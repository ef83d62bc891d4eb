#include "spill_file.hpp"

#include <stdexcept>

namespace moreau::internal {

SpillFile::~SpillFile() {
  if (file_ != nullptr) std::fclose(file_);
}

long SpillFile::Write(long offset, const double* data, std::size_t count) {
  if (file_ == nullptr) {
    file_ = std::tmpfile();
    if (file_ == nullptr) throw std::runtime_error("adjoint: cannot create a checkpoint file");
  }
  if (std::fseek(file_, offset, SEEK_SET) != 0) {
    throw std::runtime_error("adjoint: cannot seek in the checkpoint file");
  }
  if (std::fwrite(data, sizeof(double), count, file_) != count) {
    throw std::runtime_error("adjoint: cannot write the checkpoint file (disk full?)");
  }
  return offset + static_cast<long>(sizeof(double) * count);
}

void SpillFile::Read(long offset, double* data, std::size_t count) {
  if (file_ == nullptr || std::fseek(file_, offset, SEEK_SET) != 0) {
    throw std::runtime_error("adjoint: cannot seek in the checkpoint file");
  }
  if (std::fread(data, sizeof(double), count, file_) != count) {
    throw std::runtime_error("adjoint: cannot read the checkpoint file");
  }
}

}  // namespace moreau::internal
