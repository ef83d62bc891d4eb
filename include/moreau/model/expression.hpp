#pragma once
/// @file
/// Model functions written as text ("x2 - floor", "heat - decay*x"), with exact derivatives.
///
/// Grammar: numbers, + - * / ^ (right-associative, binding tighter than unary minus: -x^2 is
/// -(x^2)), unary minus and plus, parentheses, the functions sin cos tan asin acos atan atan2
/// sinh cosh tanh exp log sqrt pow hypot, the constants pi and e, and names: states, inputs,
/// parameters, named intermediate expressions ("defs") and t. Nonsmooth functions (abs, sign,
/// min, max, floor, ceil, comparisons, conditionals) are refused with a message pointing to the
/// effect that models them: a simulator of nonsmooth systems needs to see the switch.
///
/// Every expression of a model is parsed once into one expression graph in which identical
/// subexpressions are one node (hash-consing), defs included; each model function is then the
/// list of nodes its outputs reach, in topological order, evaluated by a loop over a scratch
/// array of the scalar type T. The function is a SmoothFunction like a compiled lambda: values
/// for T = double, Jacobians and weighted Hessians by the forward-mode AD of core/dual.hpp,
/// exact to round-off (no finite differences, no symbolic expansion).

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"

namespace moreau {

/// Where names in expressions point.
struct ExpressionSymbols {
  std::vector<std::string> states;      ///< x[i]
  std::vector<std::string> inputs;      ///< u[i]
  std::vector<std::string> parameters;  ///< p[i]
  /// Named intermediate expressions (may use each other; cycles are errors).
  std::map<std::string, std::string> defs;
};

/// Where an expression came from, for messages: "<source>:<line>:<column>: <what>" with the
/// column of the offending character when `line` > 0, else "<source>: <what>".
struct ExpressionOrigin {
  std::string source;    ///< file name (or "<string>")
  std::string key_path;  ///< e.g. "effects[0].constraints[1]"
  /// Line of the expression in the file (0: not from a file).
  int line = 0;
  int column = 0;  ///< column of the expression's first character
};

namespace internal {
struct ExpressionGraph;
}

/// A set of model expressions over one symbol table, compiled into SmoothFunctions that share
/// the parse (defs are parsed once). Throws std::invalid_argument with the origin and the
/// column for syntax errors, unknown names (suggesting the closest valid one), defs that refer
/// to themselves, duplicate names and nonsmooth functions.
class ExpressionModel {
 public:
  /// A model over `symbols`; `source` names the file (or "<string>") in messages.
  explicit ExpressionModel(ExpressionSymbols symbols, std::string source = "<string>");
  ~ExpressionModel();
  /// Move construction.
  ExpressionModel(ExpressionModel&&) noexcept;
  /// Move assignment.
  ExpressionModel& operator=(ExpressionModel&&) noexcept;

  /// Sets where the defs came from (for messages about them).
  void SetDefOrigin(const std::string& def, const ExpressionOrigin& origin);

  /// A function with one output per expression.
  SmoothFunction Function(const std::string& name, const std::vector<std::string>& expressions,
                          const std::vector<ExpressionOrigin>& origins);

  /// The value of an expression that may use parameters (at `parameter_values`), pi and e
  /// but no states, inputs or t (initial values, horizons).
  double Constant(const std::string& expression, const ExpressionOrigin& origin,
                  const std::vector<double>& parameter_values);

  /// Number of distinct nodes in the shared graph (for tests of the sharing).
  int num_nodes() const;

 private:
  std::unique_ptr<internal::ExpressionGraph> graph_;
};

/// The name in `candidates` closest to `name` (Levenshtein distance, at most a third of the
/// longer length), or "" if none is close.
std::string ClosestName(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace moreau
