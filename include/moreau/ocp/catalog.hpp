#pragma once
/// @file
/// The catalog of example optimal control problems (examples/ocp), used by `moreau ocp`, the
/// tests and the benchmarks. Target: moreau::ocp_problems.

#include <functional>
#include <string>
#include <vector>

#include "moreau/ocp/ocp.hpp"

namespace moreau {

/// A built-in optimal control problem: its name, a one-line summary, its factory and the options it
/// is solved with.
struct OcpDefinition {
  std::string name;     ///< command-line name, e.g. "wave_rider"
  std::string summary;  ///< one line for `moreau list`
  /// Makes the problem.
  std::function<OcpProblem()> make;
  /// The options this problem is solved with by `moreau ocp` (command-line flags override
  /// them), the tests and the benchmarks: the defaults plus what the problem needs (a
  /// homotopy, docs/ocp.md).
  std::function<OcpOptions()> options;
};

/// All problems, in the order `moreau list` shows them.
const std::vector<OcpDefinition>& OcpCatalog();
/// The problem with this name. Throws std::invalid_argument naming the unknown problem and
/// listing the available ones.
OcpProblem MakeOcpProblem(const std::string& name);
/// The options of the problem with this name (OcpDefinition::options). Throws
/// std::invalid_argument like MakeOcpProblem.
OcpOptions MakeOcpOptions(const std::string& name);

}  // namespace moreau
