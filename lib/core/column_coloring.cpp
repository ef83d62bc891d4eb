#include "column_coloring.hpp"

#include <ColPack/ColPackHeaders.h>

#include <algorithm>

#include "moreau/core/error.hpp"

namespace moreau::internal {

std::vector<int> ColorColumnsDistanceTwo(int num_columns, const std::vector<int>& row_start,
                                         const std::vector<int>& column_index, int* num_colors) {
  const int num_rows = static_cast<int>(row_start.size()) - 1;
  MOREAU_ASSERT(num_rows >= 0 && row_start.back() == static_cast<int>(column_index.size()),
                "malformed pattern handed to the column colouring");
  std::vector<int> colors(static_cast<std::size_t>(num_columns), -1);
  *num_colors = 0;
  if (column_index.empty()) return colors;

  // ColPack's row-compressed input ("ADOL-C format"): row r is an array whose first entry is its
  // length. (Its CSR input, SRC_MEM_CSR, creates one column too many in ColPack 1.0.10.)
  std::vector<unsigned int> storage;
  storage.reserve(column_index.size() + static_cast<std::size_t>(num_rows));
  std::vector<std::size_t> offsets(static_cast<std::size_t>(num_rows));
  for (int r = 0; r < num_rows; ++r) {
    offsets[static_cast<std::size_t>(r)] = storage.size();
    const int begin = row_start[static_cast<std::size_t>(r)];
    const int end = row_start[static_cast<std::size_t>(r) + 1];
    storage.push_back(static_cast<unsigned int>(end - begin));
    for (int e = begin; e < end; ++e) {
      const int column = column_index[static_cast<std::size_t>(e)];
      MOREAU_ASSERT(column >= 0 && column < num_columns, "column index out of range");
      storage.push_back(static_cast<unsigned int>(column));
    }
  }
  std::vector<unsigned int*> rows(static_cast<std::size_t>(num_rows));
  for (int r = 0; r < num_rows; ++r) {
    rows[static_cast<std::size_t>(r)] = storage.data() + offsets[static_cast<std::size_t>(r)];
  }

  std::vector<int> colpack_colors;
  {
    ColPack::BipartiteGraphPartialColoringInterface graph(SRC_MEM_ADOLC, rows.data(), num_rows,
                                                          num_columns);
    // The sequential variants: the default entry points of the Debian build dispatch to OpenMP
    // versions whose speculative colouring depends on thread timing (not reproducible).
    MOREAU_ASSERT(graph.ColumnSmallestLastOrdering_serial() == _TRUE, "ColPack ordering failed");
    MOREAU_ASSERT(graph.PartialDistanceTwoColumnColoring_serial() == _TRUE,
                  "ColPack colouring failed");
    graph.GetRightVertexColors(colpack_colors);
  }
  MOREAU_ASSERT(static_cast<int>(colpack_colors.size()) == num_columns,
                "ColPack returned a colouring of the wrong size");

  // Renumber the colours of the columns that occur in some row: 0, 1, ... by first use.
  std::vector<char> used(static_cast<std::size_t>(num_columns), 0);
  for (int column : column_index) used[static_cast<std::size_t>(column)] = 1;
  std::vector<int> renumbered(static_cast<std::size_t>(num_columns) + 1, -1);
  for (int column = 0; column < num_columns; ++column) {
    if (!used[static_cast<std::size_t>(column)]) continue;
    const int color = colpack_colors[static_cast<std::size_t>(column)];
    MOREAU_ASSERT(color >= 0 && color < num_columns, "ColPack left a column uncoloured");
    int& number = renumbered[static_cast<std::size_t>(color)];
    if (number < 0) number = (*num_colors)++;
    colors[static_cast<std::size_t>(column)] = number;
  }

  // Certificate: the columns of every row have distinct colours (O(entries)).
  std::vector<int> seen_in_row(static_cast<std::size_t>(*num_colors), -1);
  for (int r = 0; r < num_rows; ++r) {
    for (int e = row_start[static_cast<std::size_t>(r)];
         e < row_start[static_cast<std::size_t>(r) + 1]; ++e) {
      const int color = colors[static_cast<std::size_t>(column_index[static_cast<std::size_t>(e)])];
      MOREAU_ASSERT(seen_in_row[static_cast<std::size_t>(color)] != r,
                    "ColPack returned an invalid distance-2 colouring");
      seen_in_row[static_cast<std::size_t>(color)] = r;
    }
  }
  return colors;
}

}  // namespace moreau::internal
