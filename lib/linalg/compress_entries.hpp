#pragma once
// Triplets to a compressed-columns matrix in its kept storage, shared by DerivativeMatrix and
// SystemMatrix (their Finalize), replayed through a kept plan while the pattern stays.

#include <cstddef>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/linalg/derivative_matrix.hpp"

namespace moreau::internal {

// CompressEntries' scratch: entry positions sorted by row, then by column, and a count per row
// or column. Per thread, not per matrix: evaluations hold dozens of matrices and a thread
// compresses one at a time; kept, so that a steady sequence of evaluations does not allocate.
struct CompressScratch {
  std::vector<int> count, by_row, by_column;
};
inline CompressScratch& ThisThreadsCompressScratch() {
  thread_local CompressScratch scratch;
  return scratch;
}

// *m = the rows x cols matrix of `entries` (each with row(), col(), value()): what Eigen's
// setFromTriplets computes (compressed columns, rows increasing in each column, duplicates
// summed from left to right in the order given: the same bits), without its two temporary
// matrices per call: m's storage is reused, its capacity kept.
//
// *plan describes how the previous call filled *m (its owner keeps both and resets the plan
// when it changes *m otherwise). Entries at the positions of that call, in the same order,
// are written through the plan in one pass: the same assignments and sums in the same order,
// so the same bits. Each entry's position is checked against its slot's in *m (the slot lies
// in the entry's column and holds its row); the first entries of the plan's positions fill
// every stored slot once (as many positions as stored entries), so no stale value survives.
// Otherwise two stable counting sorts order the entries by (column, row, position) and the
// plan is recorded for the next call.
template <class Entries>
void CompressEntries(const Entries& entries, int rows, int cols, SparseMatrix* m,
                     CompressionPlan* plan) {
  const std::size_t n = entries.size();
  if (plan->rows == rows && plan->cols == cols && plan->slots.size() == n && m->rows() == rows &&
      m->cols() == cols && m->isCompressed() && m->nonZeros() == plan->nonzeros) {
    const int* outer = m->outerIndexPtr();
    const int* inner = m->innerIndexPtr();
    double* values = m->valuePtr();
    std::size_t i = 0;
    for (; i < n; ++i) {
      const auto& e = entries[i];
      const int slot = plan->slots[i];
      const int at = slot >= 0 ? slot : ~slot;
      const auto col = static_cast<int>(e.col());
      if (at < outer[col] || at >= outer[col + 1] || inner[at] != static_cast<int>(e.row())) break;
      if (slot >= 0) {
        values[at] = e.value();
      } else {
        values[at] += e.value();
      }
    }
    if (i == n) return;
    // Another pattern: compressed anew below (the values written so far are overwritten).
  }
  CompressScratch& scratch = ThisThreadsCompressScratch();
  scratch.by_row.resize(n);
  scratch.by_column.resize(n);
  std::vector<int>& count = scratch.count;
  count.assign(static_cast<std::size_t>(rows) + 1, 0);
  for (const auto& e : entries) ++count[static_cast<std::size_t>(e.row()) + 1];
  for (std::size_t r = 0; r < static_cast<std::size_t>(rows); ++r) count[r + 1] += count[r];
  for (std::size_t i = 0; i < n; ++i) {
    const auto r = static_cast<std::size_t>(entries[i].row());
    scratch.by_row[static_cast<std::size_t>(count[r]++)] = static_cast<int>(i);
  }
  count.assign(static_cast<std::size_t>(cols) + 1, 0);
  for (const auto& e : entries) ++count[static_cast<std::size_t>(e.col()) + 1];
  for (std::size_t c = 0; c < static_cast<std::size_t>(cols); ++c) count[c + 1] += count[c];
  for (int i : scratch.by_row) {
    const auto c = static_cast<std::size_t>(entries[static_cast<std::size_t>(i)].col());
    scratch.by_column[static_cast<std::size_t>(count[c]++)] = i;
  }
  const auto entry = [&](std::size_t k) -> const auto& {
    return entries[static_cast<std::size_t>(scratch.by_column[k])];
  };
  // The sorted entry k has the (column, row) of entry k - 1: a duplicate, summed.
  const auto repeats = [&](std::size_t k) {
    return k > 0 && entry(k - 1).col() == entry(k).col() && entry(k - 1).row() == entry(k).row();
  };
  m->resize(rows, cols);  // outer indices zero, no entries (their storage kept)
  int* outer = m->outerIndexPtr();
  Eigen::Index distinct = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (repeats(k)) continue;
    ++outer[entry(k).col() + 1];
    ++distinct;
  }
  for (int c = 0; c < cols; ++c) outer[c + 1] += outer[c];
  m->resizeNonZeros(distinct);
  int* inner = m->innerIndexPtr();
  double* values = m->valuePtr();
  plan->slots.resize(n);
  Eigen::Index last = -1;
  for (std::size_t k = 0; k < n; ++k) {
    const auto position = static_cast<std::size_t>(scratch.by_column[k]);
    if (repeats(k)) {
      values[last] += entry(k).value();
      plan->slots[position] = ~static_cast<int>(last);
    } else {
      ++last;
      inner[last] = static_cast<int>(entry(k).row());
      values[last] = entry(k).value();
      plan->slots[position] = static_cast<int>(last);
    }
  }
  plan->rows = rows;
  plan->cols = cols;
  plan->nonzeros = distinct;
}

}  // namespace moreau::internal
