// Scene files (TOML, read by toml++): include/moreau/model/scene_file.hpp, docs/scene-files.md.
#include "moreau/model/scene_file.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "moreau/core/error.hpp"
#include "moreau/model/expression.hpp"
#include "toml_screen.hpp"

// toml++ (Debian libtomlplusplus-dev), header-only, private to this file. Its internal
// assertions are compiled as in release builds in every build type: toml++ 3.3 asserts (and so
// aborts a debug build) on some malformed input that it otherwise rejects with a parse error
// (found by tests/model/scene_file_test.cpp's robustness run; e.g. a key position holding a
// character that is neither a key character nor a quote). The robustness run checks under
// AddressSanitizer and UndefinedBehaviorSanitizer that the parser stays memory-safe there.
#ifndef NDEBUG
#define NDEBUG
#define MOREAU_RESTORE_NDEBUG
#endif
#include <toml++/toml.h>
#ifdef MOREAU_RESTORE_NDEBUG
#undef NDEBUG
#undef MOREAU_RESTORE_NDEBUG
#endif

namespace moreau {
namespace {

constexpr std::size_t kMaxFileBytes = 16u << 20;  // a model, not a data set

// Reads one scene file, keeping the source for messages.
class SceneReader {
 public:
  SceneReader(std::string source) : source_(std::move(source)) {}

  Scene Read(const std::string& text);

 private:
  // ---- messages ---------------------------------------------------------------------------
  std::string Where(const toml::source_region& region, const std::string& path) const {
    std::string where = source_;
    if (region.begin.line > 0) {
      where += ":" + std::to_string(region.begin.line) + ":" + std::to_string(region.begin.column);
    }
    return where + (path.empty() ? "" : " (" + path + ")");
  }
  template <class... Args>
  [[noreturn]] void Fail(const toml::node& node, const std::string& path,
                         const Args&... args) const {
    ThrowInvalidArgument(Where(node.source(), path), ": ", args...);
  }
  template <class... Args>
  [[noreturn]] void FailAt(const toml::source_region& region, const std::string& path,
                           const Args&... args) const {
    ThrowInvalidArgument(Where(region, path), ": ", args...);
  }

  static std::string TypeName(const toml::node& node) {
    switch (node.type()) {
      case toml::node_type::string:
        return "a string";
      case toml::node_type::integer:
        return "an integer";
      case toml::node_type::floating_point:
        return "a number";
      case toml::node_type::boolean:
        return "a boolean";
      case toml::node_type::array:
        return "an array";
      case toml::node_type::table:
        return "a table";
      default:
        return "a date or time";
    }
  }
  static std::string Join(const std::string& path, const std::string& key) {
    return path.empty() ? key : path + "." + key;
  }
  static std::string Index(const std::string& path, std::size_t i) {
    return path + "[" + std::to_string(i) + "]";
  }

  // ---- structure ----------------------------------------------------------------------------
  void CheckKeys(const toml::table& table, const std::string& path,
                 const std::vector<std::string>& allowed) const {
    for (const auto& [key, node] : table) {
      const std::string name(key.str());
      if (std::find(allowed.begin(), allowed.end(), name) != allowed.end()) continue;
      const std::string closest = ClosestName(name, allowed);
      std::string list;
      for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
      FailAt(key.source().begin.line > 0 ? key.source() : node.source(), Join(path, name),
             "unknown key '", name, "'",
             closest.empty() ? std::string() : "; did you mean '" + closest + "'?",
             " (valid keys here: ", list, ")");
    }
  }
  const toml::node& Require(const toml::table& table, const std::string& key,
                            const std::string& path, const std::string& what) const {
    const toml::node* node = table.get(key);
    if (node == nullptr) {
      FailAt(table.source(), path, "missing required key '", key, "' (", what, ")");
    }
    return *node;
  }
  std::string String(const toml::node& node, const std::string& path) const {
    if (!node.is_string()) Fail(node, path, "expected a string, got ", TypeName(node));
    return std::string(*node.as_string());
  }
  std::string OptionalString(const toml::table& table, const std::string& key,
                             const std::string& path, const std::string& fallback = "") const {
    const toml::node* node = table.get(key);
    return node ? String(*node, Join(path, key)) : fallback;
  }
  double Number(const toml::node& node, const std::string& path) const {
    if (const auto* f = node.as_floating_point()) return f->get();
    if (const auto* i = node.as_integer()) return static_cast<double>(i->get());
    Fail(node, path, "expected a number, got ", TypeName(node));
  }
  double FiniteNumber(const toml::node& node, const std::string& path) const {
    const double value = Number(node, path);
    if (!std::isfinite(value)) Fail(node, path, "expected a finite number, got ", value);
    return value;
  }
  long Integer(const toml::node& node, const std::string& path) const {
    if (const auto* i = node.as_integer()) return static_cast<long>(i->get());
    Fail(node, path, "expected an integer, got ", TypeName(node));
  }
  const toml::array& Array(const toml::node& node, const std::string& path,
                           const std::string& what) const {
    const toml::array* array = node.as_array();
    if (array == nullptr) Fail(node, path, "expected an array (", what, "), got ", TypeName(node));
    return *array;
  }
  const toml::table& Table(const toml::node& node, const std::string& path) const {
    const toml::table* table = node.as_table();
    if (table == nullptr) Fail(node, path, "expected a table, got ", TypeName(node));
    return *table;
  }
  void RequireLength(const toml::array& array, const std::string& path, std::size_t expected,
                     const std::string& what) const {
    if (array.size() != expected) {
      FailAt(array.source(), path, "expected ", expected, " entr", expected == 1 ? "y" : "ies",
             " (", what, "), got ", array.size());
    }
  }
  std::vector<std::string> Names(const toml::node& node, const std::string& path,
                                 const std::string& what) const {
    std::vector<std::string> names;
    const toml::array& array = Array(node, path, what);
    for (std::size_t i = 0; i < array.size(); ++i) {
      const std::string name = String(*array.get(i), Index(path, i));
      CheckIdentifier(*array.get(i), Index(path, i), name);
      names.push_back(name);
    }
    return names;
  }
  void CheckIdentifier(const toml::node& node, const std::string& path,
                       const std::string& name) const {
    bool ok =
        !name.empty() && (std::isalpha(static_cast<unsigned char>(name[0])) || name[0] == '_');
    for (char c : name) ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
    if (!ok) {
      Fail(node, path, "'", name,
           "' is not a valid name (letters, digits and '_', not starting with a digit)");
    }
  }

  // An expression entry: a string, or a number (written as its exact decimal).
  std::pair<std::string, ExpressionOrigin> Expression(const toml::node& node,
                                                      const std::string& path) const {
    ExpressionOrigin origin;
    origin.source = source_;
    origin.key_path = path;
    origin.line = static_cast<int>(node.source().begin.line);
    origin.column = static_cast<int>(node.source().begin.column) + 1;  // after the quote
    if (node.is_string()) return {std::string(*node.as_string()), origin};
    if (node.is_number()) {
      const double value = Number(node, path);
      if (!std::isfinite(value)) Fail(node, path, "expected a finite value, got ", value);
      std::ostringstream text;
      text.precision(17);
      text << value;
      return {text.str(), origin};
    }
    Fail(node, path, "expected an expression (a string) or a number, got ", TypeName(node));
  }
  SmoothFunction Functions(const toml::node& node, const std::string& path, const std::string& name,
                           std::size_t expected, const std::string& what) {
    const toml::array& array = Array(node, path, what);
    if (expected != std::string::npos) RequireLength(array, path, expected, what);
    if (array.empty()) Fail(node, path, "expected at least one expression (", what, ")");
    std::vector<std::string> texts;
    std::vector<ExpressionOrigin> origins;
    for (std::size_t i = 0; i < array.size(); ++i) {
      auto [text, origin] = Expression(*array.get(i), Index(path, i));
      texts.push_back(text);
      origins.push_back(origin);
    }
    return model_->Function(name, texts, origins);
  }
  // A number, or a constant expression of the parameters.
  double Value(const toml::node& node, const std::string& path) {
    if (node.is_number()) return FiniteNumber(node, path);
    auto [text, origin] = Expression(node, path);
    const double value = model_->Constant(text, origin, parameter_values_);
    if (!std::isfinite(value)) {
      Fail(node, path, "'", text, "' evaluates to ", value, "; expected a finite value");
    }
    return value;
  }
  int ParameterIndex(const toml::node& node, const std::string& path, const Scene& scene) const {
    const std::string name = String(node, path);
    const int index = scene.FindParameter(name);
    if (index < 0) {
      std::vector<std::string> names;
      for (const ParameterSpec& p : scene.parameters) names.push_back(p.name);
      const std::string closest = ClosestName(name, names);
      Fail(node, path, "unknown parameter '", name, "'",
           closest.empty() ? std::string() : "; did you mean '" + closest + "'?",
           " (thresholds are parameters, declared in [[parameters]])");
    }
    return index;
  }

  // ---- sections -------------------------------------------------------------------------
  void ReadDefaults(const toml::node& node, Scene* scene);
  void ReadParameters(const toml::table& root, Scene* scene);
  void ReadInputs(const toml::table& root, Scene* scene);
  void ReadEffect(const toml::table& table, const std::string& path, Scene* scene);
  void ReadMovingSet(const toml::table& table, const std::string& path, Scene* scene);
  void ReadSwitching(const toml::table& table, const std::string& path, Scene* scene);
  void ReadHysteresis(const toml::table& table, const std::string& path, Scene* scene);
  void ReadPathConstraints(const toml::table& table, const std::string& path, Scene* scene);
  void ReadComplementarity(const toml::table& table, const std::string& path, Scene* scene);
  // [view]: names, units and planar geometry, each problem located (end of this file).
  void ReadView(const toml::table& table, Scene* scene);
  void ReadViewBody(const toml::table& table, const std::string& path, Scene* scene);
  void ReadViewObstacle(const toml::table& table, const std::string& path, Scene* scene);
  std::string StateName(const toml::node& node, const std::string& path, const Scene& scene) const;
  // A matrix of expressions given as `rows` arrays of `cols` entries, row-major.
  SmoothFunction MatrixFunction(const toml::node& node, const std::string& path,
                                const std::string& name, std::size_t rows, std::size_t cols,
                                const std::string& what);
  std::vector<std::string> ConstraintNames(const toml::table& table, const std::string& path,
                                           std::size_t count, const std::string& prefix) const;

  std::string source_;
  std::unique_ptr<ExpressionModel> model_;
  std::vector<double> parameter_values_;
  const toml::node* x0_node_ = nullptr;
};

void SceneReader::ReadParameters(const toml::table& root, Scene* scene) {
  const toml::node* node = root.get("parameters");
  if (node == nullptr) return;
  const toml::array& array = Array(*node, "parameters", "[[parameters]] tables");
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string path = Index("parameters", i);
    const toml::table& table = Table(*array.get(i), path);
    CheckKeys(table, path, {"name", "value", "description"});
    const toml::node& name_node = Require(table, "name", path, "the parameter's name");
    const std::string name = String(name_node, Join(path, "name"));
    CheckIdentifier(name_node, Join(path, "name"), name);
    const double value =
        FiniteNumber(Require(table, "value", path, "a number"), Join(path, "value"));
    scene->AddParameter(name, value, OptionalString(table, "description", path));
  }
}

void SceneReader::ReadInputs(const toml::table& root, Scene* scene) {
  const toml::node* node = root.get("inputs");
  if (node == nullptr) return;
  const toml::array& array = Array(*node, "inputs", "[[inputs]] tables");
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string path = Index("inputs", i);
    const toml::table& table = Table(*array.get(i), path);
    CheckKeys(table, path,
              {"name", "kind", "value", "values", "breakpoints", "lower", "upper", "initial_guess",
               "description"});
    InputSpec input;
    const toml::node& name_node = Require(table, "name", path, "the input's name");
    input.name = String(name_node, Join(path, "name"));
    CheckIdentifier(name_node, Join(path, "name"), input.name);
    const std::string kind = OptionalString(table, "kind", path, "control");
    if (kind == "control") {
      input.kind = InputSpec::Kind::kControl;
    } else if (kind == "algebraic") {
      input.kind = InputSpec::Kind::kAlgebraic;
    } else {
      Fail(*table.get("kind"), Join(path, "kind"), "expected \"control\" or \"algebraic\", got \"",
           kind, "\"");
    }
    if (const toml::node* value = table.get("value")) {
      if (table.get("values")) {
        Fail(*value, Join(path, "value"),
             "give either 'value' (constant) or 'values' with "
             "'breakpoints', not both");
      }
      input.signal.values = {FiniteNumber(*value, Join(path, "value"))};
    } else if (const toml::node* values = table.get("values")) {
      const toml::array& v = Array(*values, Join(path, "values"), "the signal's values");
      input.signal.values.clear();
      for (std::size_t k = 0; k < v.size(); ++k) {
        input.signal.values.push_back(FiniteNumber(*v.get(k), Index(Join(path, "values"), k)));
      }
      std::vector<double> breakpoints;
      if (const toml::node* b = table.get("breakpoints")) {
        const toml::array& bp =
            Array(*b, Join(path, "breakpoints"), "times where the value changes");
        for (std::size_t k = 0; k < bp.size(); ++k) {
          breakpoints.push_back(FiniteNumber(*bp.get(k), Index(Join(path, "breakpoints"), k)));
          if (k > 0 && breakpoints[k] <= breakpoints[k - 1]) {
            Fail(*bp.get(k), Index(Join(path, "breakpoints"), k),
                 "breakpoints must increase strictly, got ", breakpoints[k], " after ",
                 breakpoints[k - 1]);
          }
        }
      }
      if (v.size() != breakpoints.size() + 1) {
        Fail(*values, Join(path, "values"), "expected one value more than breakpoints (",
             breakpoints.size() + 1, "), got ", v.size());
      }
      input.signal.breakpoints = breakpoints;
    } else if (table.get("breakpoints")) {
      Fail(*table.get("breakpoints"), Join(path, "breakpoints"),
           "'breakpoints' needs 'values' (one more than breakpoints)");
    }
    if (const toml::node* lower = table.get("lower"))
      input.lower = Number(*lower, Join(path, "lower"));
    if (const toml::node* upper = table.get("upper"))
      input.upper = Number(*upper, Join(path, "upper"));
    if (const toml::node* guess = table.get("initial_guess")) {
      input.initial_guess = FiniteNumber(*guess, Join(path, "initial_guess"));
    }
    input.description = OptionalString(table, "description", path);
    scene->inputs.push_back(input);
  }
}

std::vector<std::string> SceneReader::ConstraintNames(const toml::table& table,
                                                      const std::string& path, std::size_t count,
                                                      const std::string& key) const {
  const toml::node* node = table.get(key);
  if (node == nullptr) {
    std::vector<std::string> names;
    for (std::size_t j = 0; j < count; ++j) names.push_back("c" + std::to_string(j + 1));
    return names;
  }
  const std::vector<std::string> names = Names(*node, Join(path, key), "one name per component");
  RequireLength(*node->as_array(), Join(path, key), count, "one name per component");
  return names;
}

void SceneReader::ReadMovingSet(const toml::table& table, const std::string& path, Scene* scene) {
  CheckKeys(table, path, {"kind", "name", "constraints", "constraint_names", "projection_basis"});
  MovingSet set;
  set.name = String(Require(table, "name", path, "the effect's name"), Join(path, "name"));
  const toml::node& constraints = Require(table, "constraints", path, "c(x, t) >= 0");
  set.constraints = Functions(constraints, Join(path, "constraints"), set.name + ".c",
                              std::string::npos, "constraints c(x, t) >= 0");
  set.constraint_names = ConstraintNames(
      table, path, static_cast<std::size_t>(set.constraints.num_outputs()), "constraint_names");
  if (const toml::node* basis = table.get("projection_basis")) {
    const std::string basis_path = Join(path, "projection_basis");
    const toml::array& rows = Array(*basis, basis_path, "n_x rows of the basis E");
    RequireLength(rows, basis_path, static_cast<std::size_t>(scene->num_states()),
                  "one row per state");
    std::size_t columns = 0;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const toml::array& row = Array(*rows.get(i), Index(basis_path, i), "a row of E");
      if (i == 0) columns = row.size();
      RequireLength(row, Index(basis_path, i), columns, "the columns of E");
      if (i == 0)
        set.projection_basis.resize(scene->num_states(), static_cast<Eigen::Index>(columns));
      for (std::size_t j = 0; j < row.size(); ++j) {
        set.projection_basis(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
            FiniteNumber(*row.get(j), Index(Index(basis_path, i), j));
      }
    }
  }
  scene->effects.push_back(set);
}

void SceneReader::ReadSwitching(const toml::table& table, const std::string& path, Scene* scene) {
  CheckKeys(table, path,
            {"kind", "name", "surfaces", "surface_names", "modes", "mode_names", "below", "above"});
  SwitchingSurfaces sw;
  sw.name = String(Require(table, "name", path, "the effect's name"), Join(path, "name"));
  const toml::node& surfaces = Require(table, "surfaces", path, "switching functions c(x, t)");
  sw.surfaces = Functions(surfaces, Join(path, "surfaces"), sw.name + ".c", std::string::npos,
                          "switching functions c(x, t)");
  const std::size_t nc = static_cast<std::size_t>(sw.surfaces.num_outputs());
  if (nc > 10) Fail(surfaces, Join(path, "surfaces"), "at most 10 surfaces (2^10 modes), got ", nc);
  sw.surface_names = ConstraintNames(table, path, nc, "surface_names");
  const std::size_t num_modes = std::size_t{1} << nc;
  const std::size_t nx = static_cast<std::size_t>(scene->num_states());
  const toml::node* modes = table.get("modes");
  const toml::node* below = table.get("below");
  const toml::node* above = table.get("above");
  if ((modes != nullptr) == (below != nullptr || above != nullptr) ||
      (modes == nullptr && (below == nullptr || above == nullptr))) {
    FailAt(table.source(), path,
           "give either 'modes' (all 2^n fields, mode k = sum_j [c_j > 0] 2^j) or both 'below' "
           "and 'above' (one field per surface on each side)");
  }
  // The field of each mode as expression text (the shorthand adds one field per surface).
  std::vector<std::vector<std::pair<std::string, ExpressionOrigin>>> fields(num_modes);
  if (modes != nullptr) {
    const std::string modes_path = Join(path, "modes");
    const toml::array& list = Array(*modes, modes_path, "2^n mode fields");
    RequireLength(list, modes_path, num_modes, "2^n mode fields for n surfaces");
    for (std::size_t k = 0; k < num_modes; ++k) {
      const toml::array& field = Array(*list.get(k), Index(modes_path, k), "a field, n_x entries");
      RequireLength(field, Index(modes_path, k), nx, "one entry per state");
      for (std::size_t i = 0; i < nx; ++i) {
        fields[k].push_back(Expression(*field.get(i), Index(Index(modes_path, k), i)));
      }
    }
  } else {
    std::vector<std::vector<std::pair<std::string, ExpressionOrigin>>> side[2];
    const toml::node* nodes[2] = {below, above};
    const char* keys[2] = {"below", "above"};
    for (int s = 0; s < 2; ++s) {
      const std::string side_path = Join(path, keys[s]);
      const toml::array& list = Array(*nodes[s], side_path, "one field per surface");
      RequireLength(list, side_path, nc, "one field per surface");
      for (std::size_t j = 0; j < nc; ++j) {
        const toml::array& field = Array(*list.get(j), Index(side_path, j), "a field, n_x entries");
        RequireLength(field, Index(side_path, j), nx, "one entry per state");
        side[s].emplace_back();
        for (std::size_t i = 0; i < nx; ++i) {
          side[s][j].push_back(Expression(*field.get(i), Index(Index(side_path, j), i)));
        }
      }
    }
    for (std::size_t k = 0; k < num_modes; ++k) {
      for (std::size_t i = 0; i < nx; ++i) {
        std::string text;
        ExpressionOrigin origin;
        for (std::size_t j = 0; j < nc; ++j) {
          const auto& [part, part_origin] = side[(k >> j) & 1u][j][i];
          text += (j ? " + (" : "(") + part + ")";
          if (j == 0) origin = part_origin;
        }
        origin.column = 0;  // the sum is ours: point at the entry, not into it
        fields[k].push_back({text, origin});
      }
    }
  }
  for (std::size_t k = 0; k < num_modes; ++k) {
    std::vector<std::string> texts;
    std::vector<ExpressionOrigin> origins;
    for (auto& [text, origin] : fields[k]) {
      texts.push_back(text);
      origins.push_back(origin);
    }
    sw.modes.push_back(model_->Function(sw.name + ".f" + std::to_string(k), texts, origins));
  }
  if (const toml::node* names = table.get("mode_names")) {
    sw.mode_names = Names(*names, Join(path, "mode_names"), "one name per mode");
    RequireLength(*names->as_array(), Join(path, "mode_names"), num_modes, "one name per mode");
  } else {
    for (std::size_t k = 0; k < num_modes; ++k) sw.mode_names.push_back("mode" + std::to_string(k));
  }
  scene->effects.push_back(sw);
}

void SceneReader::ReadHysteresis(const toml::table& table, const std::string& path, Scene* scene) {
  CheckKeys(table, path,
            {"kind", "name", "input", "lower_threshold", "upper_threshold", "mode_a", "mode_b",
             "initial_memory", "auxiliary_gain"});
  HysteresisRelay relay;
  relay.name = String(Require(table, "name", path, "the effect's name"), Join(path, "name"));
  const toml::node& input = Require(table, "input", path, "the relay's input psi(x, t)");
  auto [input_text, input_origin] = Expression(input, Join(path, "input"));
  relay.input = model_->Function(relay.name + ".input", {input_text}, {input_origin});
  relay.lower_threshold =
      ParameterIndex(Require(table, "lower_threshold", path, "a parameter name"),
                     Join(path, "lower_threshold"), *scene);
  relay.upper_threshold =
      ParameterIndex(Require(table, "upper_threshold", path, "a parameter name"),
                     Join(path, "upper_threshold"), *scene);
  const std::size_t nx = static_cast<std::size_t>(scene->num_states());
  relay.mode_a = Functions(Require(table, "mode_a", path, "f_A, n_x expressions"),
                           Join(path, "mode_a"), relay.name + ".f_A", nx, "f_A: one per state");
  relay.mode_b = Functions(Require(table, "mode_b", path, "f_B, n_x expressions"),
                           Join(path, "mode_b"), relay.name + ".f_B", nx, "f_B: one per state");
  if (const toml::node* memory = table.get("initial_memory")) {
    const long w0 = Integer(*memory, Join(path, "initial_memory"));
    if (w0 != 0 && w0 != 1)
      Fail(*memory, Join(path, "initial_memory"), "expected 0 or 1, got ", w0);
    relay.initial_memory = static_cast<int>(w0);
  }
  if (const toml::node* gain = table.get("auxiliary_gain")) {
    relay.auxiliary_gain = FiniteNumber(*gain, Join(path, "auxiliary_gain"));
  }
  scene->effects.push_back(relay);
}

void SceneReader::ReadPathConstraints(const toml::table& table, const std::string& path,
                                      Scene* scene) {
  CheckKeys(table, path,
            {"kind", "name", "constraints", "constraint_names", "state_lower", "state_upper"});
  PathConstraints dai;
  dai.name = String(Require(table, "name", path, "the effect's name"), Join(path, "name"));
  const toml::node& constraints = Require(table, "constraints", path, "phi(x, u, t) <= 0");
  dai.constraints = Functions(constraints, Join(path, "constraints"), dai.name + ".phi",
                              std::string::npos, "phi(x, u, t) <= 0");
  dai.constraint_names = ConstraintNames(
      table, path, static_cast<std::size_t>(dai.constraints.num_outputs()), "constraint_names");
  for (const char* key : {"state_lower", "state_upper"}) {
    const toml::node* node = table.get(key);
    if (node == nullptr) continue;
    const toml::array& list = Array(*node, Join(path, key), "one bound per state");
    RequireLength(list, Join(path, key), static_cast<std::size_t>(scene->num_states()),
                  "one bound per state (inf for none)");
    Vector bounds(scene->num_states());
    for (std::size_t i = 0; i < list.size(); ++i) {
      bounds[static_cast<Eigen::Index>(i)] = Number(*list.get(i), Index(Join(path, key), i));
    }
    (std::string(key) == "state_lower" ? dai.state_lower : dai.state_upper) = bounds;
  }
  scene->effects.push_back(dai);
}

SmoothFunction SceneReader::MatrixFunction(const toml::node& node, const std::string& path,
                                           const std::string& name, std::size_t rows,
                                           std::size_t cols, const std::string& what) {
  const toml::array& list = Array(node, path, what);
  RequireLength(list, path, rows, what);
  std::vector<std::string> texts;
  std::vector<ExpressionOrigin> origins;
  for (std::size_t i = 0; i < rows; ++i) {
    const toml::array& row = Array(*list.get(i), Index(path, i), "a row of " + what);
    RequireLength(row, Index(path, i), cols, "one entry per pair");
    for (std::size_t j = 0; j < cols; ++j) {
      auto [text, origin] = Expression(*row.get(j), Index(Index(path, i), j));
      texts.push_back(text);
      origins.push_back(origin);
    }
  }
  return model_->Function(name, texts, origins);
}

void SceneReader::ReadComplementarity(const toml::table& table, const std::string& path,
                                      Scene* scene) {
  CheckKeys(table, path, {"kind", "name", "pair_names", "output", "input_matrix", "feedthrough"});
  Complementarity lcs;
  lcs.name = String(Require(table, "name", path, "the effect's name"), Join(path, "name"));
  const toml::node& output = Require(table, "output", path, "g(x, t), one per pair");
  lcs.output = Functions(output, Join(path, "output"), lcs.name + ".g", std::string::npos,
                         "g(x, t), one expression per pair");
  const std::size_t m = static_cast<std::size_t>(lcs.output.num_outputs());
  lcs.pair_names = ConstraintNames(table, path, m, "pair_names");
  const std::size_t nx = static_cast<std::size_t>(scene->num_states());
  lcs.input_matrix =
      MatrixFunction(Require(table, "input_matrix", path, "B(x, t): n_x rows of m entries"),
                     Join(path, "input_matrix"), lcs.name + ".B", nx, m,
                     "B: one row per state, one entry per pair");
  if (const toml::node* d = table.get("feedthrough")) {
    lcs.feedthrough = MatrixFunction(*d, Join(path, "feedthrough"), lcs.name + ".D", m, m,
                                     "D: one row per pair, one entry per pair");
  }
  scene->effects.push_back(lcs);
}

void SceneReader::ReadEffect(const toml::table& table, const std::string& path, Scene* scene) {
  const toml::node& kind_node =
      Require(table, "kind", path,
              "moving_set, switching, hysteresis, path_constraints or complementarity");
  const std::string kind = String(kind_node, Join(path, "kind"));
  // One reader per effect kind.
  if (kind == "moving_set") return ReadMovingSet(table, path, scene);
  if (kind == "switching") return ReadSwitching(table, path, scene);
  if (kind == "hysteresis") return ReadHysteresis(table, path, scene);
  if (kind == "path_constraints") return ReadPathConstraints(table, path, scene);
  if (kind == "complementarity") return ReadComplementarity(table, path, scene);
  const std::vector<std::string> kinds = {"moving_set", "switching", "hysteresis",
                                          "path_constraints", "complementarity"};
  const std::string closest = ClosestName(kind, kinds);
  Fail(kind_node, Join(path, "kind"), "unknown effect kind '", kind, "'",
       closest.empty() ? std::string() : "; did you mean '" + closest + "'?",
       " (kinds: moving_set, switching, hysteresis, path_constraints, complementarity)");
}

// [defaults]: the integrator settings the scene's author knows (SceneDefaults). Values are
// numbers or constant expressions of the parameters (evaluated here, with the file's values).
void SceneReader::ReadDefaults(const toml::node& node, Scene* scene) {
  const toml::table& table = Table(node, "defaults");
  CheckKeys(table, "defaults", {"rtol", "atol", "h0", "h_max", "output_times", "output_dt"});
  SceneDefaults& defaults = scene->defaults;
  auto positive = [&](const char* key, double* target) {
    const toml::node* value = table.get(key);
    if (value == nullptr) return;
    const std::string path = Join("defaults", key);
    *target = Value(*value, path);
    if (!(*target > 0.0)) Fail(*value, path, "expected a positive value, got ", *target);
  };
  positive("rtol", &defaults.relative_tolerance);
  positive("atol", &defaults.absolute_tolerance);
  positive("h0", &defaults.initial_step);
  positive("h_max", &defaults.max_step);
  positive("output_dt", &defaults.output_step);
  if (const toml::node* rtol = table.get("rtol"); rtol && !(defaults.relative_tolerance < 1.0)) {
    Fail(*rtol, "defaults.rtol", "expected a relative tolerance below 1, got ",
         defaults.relative_tolerance);
  }
  if (const toml::node* times = table.get("output_times")) {
    const toml::array& list = Array(*times, "defaults.output_times", "output times in [t0, tf]");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string path = Index("defaults.output_times", i);
      const double t = Value(*list.get(i), path);
      if (t < scene->initial_time || t > scene->final_time) {
        Fail(*list.get(i), path, "output time ", t, " is outside [t0, tf] = [", scene->initial_time,
             ", ", scene->final_time, "]");
      }
      defaults.output_times.push_back(t);
    }
  }
}

Scene SceneReader::Read(const std::string& text) {
  RequireArgument(text.size() <= kMaxFileBytes, source_, ": file larger than ", kMaxFileBytes,
                  " bytes");
  detail::ScreenTomlText(text, source_);  // keeps toml++ 3.3 off its undefined behaviour
  toml::table root;
  try {
    root = toml::parse(text, source_);
  } catch (const toml::parse_error& error) {
    FailAt(error.source(), "", "TOML syntax error: ", error.description());
  }
  CheckKeys(root, "",
            {"name", "description", "t0", "tf", "states", "x0", "dynamics", "time_scale_input",
             "parameters", "inputs", "defs", "defaults", "effects", "view"});
  Scene scene;
  const toml::node& name_node = Require(root, "name", "", "the scene's name");
  scene.name = String(name_node, "name");
  if (scene.name.empty()) Fail(name_node, "name", "the scene's name must not be empty");
  scene.description = OptionalString(root, "description", "");
  ReadParameters(root, &scene);
  ReadInputs(root, &scene);
  const toml::node& states = Require(root, "states", "", "the state names, e.g. [\"x1\", \"x2\"]");
  scene.state_names = Names(states, "states", "state names");
  if (scene.state_names.empty()) Fail(states, "states", "a scene needs at least one state");

  // Names, each declared once (with where), then the expression model over them.
  ExpressionSymbols symbols;
  symbols.states = scene.state_names;
  for (const InputSpec& input : scene.inputs) symbols.inputs.push_back(input.name);
  for (const ParameterSpec& p : scene.parameters) symbols.parameters.push_back(p.name);
  std::map<std::string, std::string> declared;
  auto declare = [&](const std::string& name, const std::string& kind, const toml::node& node,
                     const std::string& path) {
    for (const char* reserved : {"t", "pi", "e"}) {
      if (name == reserved) Fail(node, path, "'", name, "' is reserved (time t, constants pi, e)");
    }
    const auto [it, inserted] = declared.emplace(name, kind);
    if (!inserted)
      Fail(node, path, "duplicate name '", name, "' (", it->second, " and ", kind, ")");
  };
  const toml::array& state_array = *states.as_array();
  for (std::size_t i = 0; i < state_array.size(); ++i) {
    declare(scene.state_names[i], "a state", *state_array.get(i), Index("states", i));
  }
  if (const toml::node* inputs = root.get("inputs")) {
    for (std::size_t i = 0; i < inputs->as_array()->size(); ++i) {
      const toml::table& t = *inputs->as_array()->get(i)->as_table();
      declare(scene.inputs[i].name, "an input", *t.get("name"), Index("inputs", i) + ".name");
    }
  }
  if (const toml::node* params = root.get("parameters")) {
    for (std::size_t i = 0; i < params->as_array()->size(); ++i) {
      const toml::table& t = *params->as_array()->get(i)->as_table();
      declare(scene.parameters[i].name, "a parameter", *t.get("name"),
              Index("parameters", i) + ".name");
    }
  }
  std::map<std::string, ExpressionOrigin> def_origins;
  if (const toml::node* defs = root.get("defs")) {
    const toml::table& table = Table(*defs, "defs");
    for (const auto& [key, node] : table) {
      const std::string name(key.str());
      const std::string path = "defs." + name;
      CheckIdentifier(node, path, name);
      declare(name, "a def", node, path);
      auto [def_text, origin] = Expression(node, path);
      symbols.defs[name] = def_text;
      def_origins[name] = origin;
    }
  }
  model_ = std::make_unique<ExpressionModel>(symbols, source_);
  for (const auto& [name, origin] : def_origins) model_->SetDefOrigin(name, origin);
  parameter_values_.clear();
  for (const ParameterSpec& p : scene.parameters) parameter_values_.push_back(p.value);

  // Horizon and initial state: numbers or constant expressions of the parameters.
  if (const toml::node* t0 = root.get("t0")) scene.initial_time = Value(*t0, "t0");
  scene.final_time = Value(Require(root, "tf", "", "the final time"), "tf");
  x0_node_ = &Require(root, "x0", "", "the initial state, one value per state");
  const toml::array& x0 = Array(*x0_node_, "x0", "one value per state");
  RequireLength(x0, "x0", scene.state_names.size(), "one value per state");
  scene.initial_state.resize(static_cast<Eigen::Index>(x0.size()));
  for (std::size_t i = 0; i < x0.size(); ++i) {
    scene.initial_state[static_cast<Eigen::Index>(i)] = Value(*x0.get(i), Index("x0", i));
  }
  if (const toml::node* dynamics = root.get("dynamics")) {
    scene.dynamics = Functions(*dynamics, "dynamics", scene.name + ".f", scene.state_names.size(),
                               "f(x, u, t): one expression per state");
  }
  if (const toml::node* scale = root.get("time_scale_input")) {
    const std::string input = String(*scale, "time_scale_input");
    int index = -1;
    for (int i = 0; i < scene.num_inputs(); ++i) {
      if (scene.inputs[static_cast<std::size_t>(i)].name == input) index = i;
    }
    if (index < 0 ||
        scene.inputs[static_cast<std::size_t>(index)].kind != InputSpec::Kind::kControl) {
      Fail(*scale, "time_scale_input", "expected the name of a control input, got '", input, "'");
    }
    scene.time_scale_input = index;
  }
  if (const toml::node* defaults = root.get("defaults")) ReadDefaults(*defaults, &scene);
  if (const toml::node* effects = root.get("effects")) {
    const toml::array& list = Array(*effects, "effects", "[[effects]] tables");
    std::set<std::string> names;
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string path = Index("effects", i);
      const toml::table& table = Table(*list.get(i), path);
      ReadEffect(table, path, &scene);
      const std::string& name = EffectName(scene.effects.back());
      if (!names.insert(name).second) {
        Fail(*table.get("name"), Join(path, "name"), "duplicate effect name '", name, "'");
      }
    }
  }
  if (const toml::node* view = root.get("view")) ReadView(Table(*view, "view"), &scene);
  // The scene's own checks (non-finite values at x0, x0 outside a moving set, ...), located
  // at x0 when they are about the initial state.
  try {
    ValidateScene(scene);
  } catch (const std::invalid_argument& error) {
    const std::string message = error.what();
    const bool about_x0 =
        message.find("initial") != std::string::npos || message.find("x0") != std::string::npos;
    if (about_x0) FailAt(x0_node_->source(), "x0", message);
    ThrowInvalidArgument(source_, ": ", message);
  }
  return scene;
}

// ---- [view] ----------------------------------------------------------------------------------

std::string SceneReader::StateName(const toml::node& node, const std::string& path,
                                   const Scene& scene) const {
  const std::string name = String(node, path);
  const auto& names = scene.state_names;
  if (std::find(names.begin(), names.end(), name) != names.end()) return name;
  const std::string closest = ClosestName(name, names);
  Fail(node, path, "unknown state '", name, "'",
       closest.empty() ? std::string() : "; did you mean '" + closest + "'?");
}

void SceneReader::ReadView(const toml::table& table, Scene* scene) {
  CheckKeys(table, "view", {"units", "labels", "window", "bodies", "obstacles"});
  SceneView& view = scene->view;
  for (const char* key : {"units", "labels"}) {
    const toml::node* node = table.get(key);
    if (node == nullptr) continue;
    const std::string path = Join("view", key);
    for (const auto& [state, text] : Table(*node, path)) {
      const std::string name(state.str());
      const std::string entry = Join(path, name);
      const auto& names = scene->state_names;
      if (name != "t" && std::find(names.begin(), names.end(), name) == names.end()) {
        const std::string closest = ClosestName(name, names);
        FailAt(state.source().begin.line > 0 ? state.source() : text.source(), entry,
               "unknown state '", name, "'",
               closest.empty() ? std::string() : "; did you mean '" + closest + "'?");
      }
      (std::string(key) == "units" ? view.units : view.labels)[name] = String(text, entry);
    }
  }
  if (const toml::node* window = table.get("window")) {
    const toml::array& array = Array(*window, "view.window", "xmin, xmax, ymin, ymax");
    RequireLength(array, "view.window", 4, "xmin, xmax, ymin, ymax");
    for (std::size_t i = 0; i < 4; ++i) {
      view.window.push_back(Value(*array.get(i), Index("view.window", i)));
    }
    if (!(view.window[0] < view.window[1] && view.window[2] < view.window[3])) {
      Fail(*window, "view.window", "expected xmin < xmax and ymin < ymax, got [", view.window[0],
           ", ", view.window[1], ", ", view.window[2], ", ", view.window[3], "]");
    }
  }
  if (const toml::node* bodies = table.get("bodies")) {
    const toml::array& list = Array(*bodies, "view.bodies", "[[view.bodies]] tables");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string path = Index("view.bodies", i);
      ReadViewBody(Table(*list.get(i), path), path, scene);
    }
  }
  if (const toml::node* obstacles = table.get("obstacles")) {
    const toml::array& list = Array(*obstacles, "view.obstacles", "[[view.obstacles]] tables");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string path = Index("view.obstacles", i);
      ReadViewObstacle(Table(*list.get(i), path), path, scene);
    }
  }
}

void SceneReader::ReadViewBody(const toml::table& table, const std::string& path, Scene* scene) {
  CheckKeys(table, path, {"name", "x", "y", "radius", "trail"});
  ViewBody body;
  const toml::node& name = Require(table, "name", path, "the body's name");
  body.name = String(name, Join(path, "name"));
  for (const ViewBody& other : scene->view.bodies) {
    if (other.name == body.name) {
      Fail(name, Join(path, "name"), "duplicate body name '", body.name, "'");
    }
  }
  body.x =
      StateName(Require(table, "x", path, "the state of the centre's x"), Join(path, "x"), *scene);
  if (const toml::node* y = table.get("y")) body.y = StateName(*y, Join(path, "y"), *scene);
  if (const toml::node* radius = table.get("radius")) {
    body.radius = Value(*radius, Join(path, "radius"));
    if (body.radius < 0.0) {
      Fail(*radius, Join(path, "radius"), "radius must be >= 0, got ", body.radius);
    }
  }
  if (const toml::node* trail = table.get("trail")) {
    if (!trail->is_boolean()) {
      Fail(*trail, Join(path, "trail"), "expected a boolean, got ", TypeName(*trail));
    }
    body.trail = **trail->as_boolean();
  }
  scene->view.bodies.push_back(body);
}

void SceneReader::ReadViewObstacle(const toml::table& table, const std::string& path,
                                   Scene* scene) {
  const toml::node& shape_node = Require(table, "shape", path, "\"circle\" or \"segment\"");
  const std::string shape = String(shape_node, Join(path, "shape"));
  ViewObstacle obstacle;
  std::vector<std::pair<std::string, std::size_t>> parts;  // key, number of expressions
  if (shape == "circle") {
    obstacle.shape = ViewObstacle::Shape::kCircle;
    CheckKeys(table, path, {"name", "shape", "center", "radius"});
    parts = {{"center", 2}, {"radius", 1}};
  } else if (shape == "segment") {
    obstacle.shape = ViewObstacle::Shape::kSegment;
    CheckKeys(table, path, {"name", "shape", "from", "to"});
    parts = {{"from", 2}, {"to", 2}};
  } else {
    Fail(shape_node, Join(path, "shape"), "expected \"circle\" or \"segment\", got \"", shape,
         "\"");
  }
  const toml::node& name = Require(table, "name", path, "the obstacle's name");
  obstacle.name = String(name, Join(path, "name"));
  for (const ViewObstacle& other : scene->view.obstacles) {
    if (other.name == obstacle.name) {
      Fail(name, Join(path, "name"), "duplicate obstacle name '", obstacle.name, "'");
    }
  }
  // Expressions of t and the parameters only: compiled here so that an unknown name points
  // at its line and column.
  ExpressionSymbols symbols;
  for (const ParameterSpec& p : scene->parameters) symbols.parameters.push_back(p.name);
  ExpressionModel geometry(symbols, source_);
  const Vector p = Eigen::Map<const Vector>(parameter_values_.data(),
                                            static_cast<Eigen::Index>(parameter_values_.size()));
  for (const auto& [key, count] : parts) {
    const std::string key_path = Join(path, key);
    const toml::node& node =
        Require(table, key, path, key == "radius" ? "an expression" : "[x, y]");
    std::vector<const toml::node*> entries;
    if (count == 1) {
      entries.push_back(&node);
    } else {
      const toml::array& array = Array(node, key_path, "[x, y]");
      RequireLength(array, key_path, count, "x and y");
      for (std::size_t i = 0; i < count; ++i) entries.push_back(array.get(i));
    }
    for (std::size_t i = 0; i < entries.size(); ++i) {
      const std::string entry_path = count == 1 ? key_path : Index(key_path, i);
      auto [text, origin] = Expression(*entries[i], entry_path);
      const SmoothFunction f = geometry.Function(obstacle.name, {text}, {origin});
      Vector value;
      f.Evaluate(Vector(), Vector(), scene->initial_time, p, &value);
      if (!std::isfinite(value[0])) {
        Fail(*entries[i], entry_path, "'", text, "' is not finite at t0 (got ", value[0], ")");
      }
      if (key == "radius" && value[0] < 0.0) {
        Fail(*entries[i], entry_path, "radius must be >= 0, got ", value[0], " at t0");
      }
      obstacle.expressions.push_back(text);
    }
  }
  scene->view.obstacles.push_back(obstacle);
}

}  // namespace

Scene ParseScene(const std::string& text, const std::string& source_name) {
  return SceneReader(source_name).Read(text);
}

Scene LoadScene(const std::string& path) {
  std::error_code error;
  RequireArgument(std::filesystem::is_regular_file(path, error), "cannot read scene file '", path,
                  "': no such file");
  RequireArgument(std::filesystem::file_size(path, error) <= kMaxFileBytes, path,
                  ": file larger than ", kMaxFileBytes, " bytes");
  std::ifstream in(path, std::ios::binary);
  RequireArgument(in.good(), "cannot read scene file '", path, "'");
  std::ostringstream text;
  text << in.rdbuf();
  return ParseScene(text.str(), path);
}

bool IsSceneFile(const std::string& argument) {
  const std::string suffix = ".toml";
  if (argument.size() >= suffix.size() &&
      argument.compare(argument.size() - suffix.size(), suffix.size(), suffix) == 0) {
    return true;
  }
  // A path (not a bare word, which names a built-in scene) to an existing file.
  std::error_code error;
  return argument.find('/') != std::string::npos &&
         std::filesystem::is_regular_file(argument, error);
}

}  // namespace moreau
