#include "moreau/model/view.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <unordered_set>

#include "moreau/core/error.hpp"
#include "moreau/model/expression.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

std::string ToString(ViewObstacle::Shape shape) {
  switch (shape) {
    case ViewObstacle::Shape::kCircle:
      return "circle";
    case ViewObstacle::Shape::kSegment:
      return "segment";
  }
  return "unknown";
}

int NumExpressions(ViewObstacle::Shape shape) {
  return shape == ViewObstacle::Shape::kCircle ? 3 : 4;
}

namespace {

// Crowds have 10^4 bodies and 2 10^4 states: a set, not a linear search per name.
void RequireState(const Scene& scene, const std::unordered_set<std::string>& states,
                  const std::string& name, const std::string& what) {
  if (states.count(name) > 0) return;
  const std::string closest = ClosestName(name, scene.state_names);
  ThrowInvalidArgument(scene.name, ": view: ", what, " '", name, "' is not a state",
                       closest.empty() ? std::string() : "; did you mean '" + closest + "'?");
}

}  // namespace

SmoothFunction ViewObstacleFunction(const Scene& scene) {
  if (scene.view.obstacles.empty()) return {};
  ExpressionSymbols symbols;
  for (const ParameterSpec& p : scene.parameters) symbols.parameters.push_back(p.name);
  ExpressionModel model(symbols, scene.name);
  std::vector<std::string> texts;
  std::vector<ExpressionOrigin> origins;
  for (const ViewObstacle& obstacle : scene.view.obstacles) {
    RequireArgument(static_cast<int>(obstacle.expressions.size()) == NumExpressions(obstacle.shape),
                    scene.name, ": view: obstacle '", obstacle.name, "' (",
                    ToString(obstacle.shape), ") needs ", NumExpressions(obstacle.shape),
                    " expressions, got ", obstacle.expressions.size());
    for (std::size_t k = 0; k < obstacle.expressions.size(); ++k) {
      texts.push_back(obstacle.expressions[k]);
      ExpressionOrigin origin;
      origin.source = scene.name;
      origin.key_path = "view.obstacles." + obstacle.name + "[" + std::to_string(k) + "]";
      origins.push_back(origin);
    }
  }
  if (texts.empty()) return {};
  return model.Function(scene.name + ".view", texts, origins);
}

void ValidateView(const Scene& scene) {
  const SceneView& view = scene.view;
  const std::unordered_set<std::string> states(scene.state_names.begin(), scene.state_names.end());
  // "t" names the unit and label of time.
  for (const auto& [name, unit] : view.units) {
    if (name != "t") RequireState(scene, states, name, "unit of");
  }
  for (const auto& [name, label] : view.labels) {
    if (name != "t") RequireState(scene, states, name, "label of");
  }
  std::set<std::string> names;
  for (const ViewBody& body : view.bodies) {
    RequireArgument(!body.name.empty(), scene.name, ": view: a body needs a name");
    RequireArgument(names.insert(body.name).second, scene.name, ": view: duplicate body name '",
                    body.name, "'");
    RequireState(scene, states, body.x, "body '" + body.name + "': x");
    if (!body.y.empty()) RequireState(scene, states, body.y, "body '" + body.name + "': y");
    RequireArgument(std::isfinite(body.radius) && body.radius >= 0.0, scene.name, ": view: body '",
                    body.name, "': radius must be finite and >= 0, got ", body.radius);
  }
  names.clear();
  for (const ViewObstacle& obstacle : view.obstacles) {
    RequireArgument(!obstacle.name.empty(), scene.name, ": view: an obstacle needs a name");
    RequireArgument(names.insert(obstacle.name).second, scene.name,
                    ": view: duplicate obstacle name '", obstacle.name, "'");
  }
  const SmoothFunction geometry = ViewObstacleFunction(scene);  // compiles: names, syntax
  if (!geometry.empty()) {
    Vector out;
    geometry.Evaluate(Vector(), Vector(), scene.initial_time, scene.ParameterValues(), &out);
    int k = 0;
    for (const ViewObstacle& obstacle : view.obstacles) {
      for (int i = 0; i < NumExpressions(obstacle.shape); ++i, ++k) {
        RequireArgument(std::isfinite(out[k]), scene.name, ": view: obstacle '", obstacle.name,
                        "': expression '", obstacle.expressions[static_cast<std::size_t>(i)],
                        "' is not finite at t0 (got ", out[k], ")");
      }
      if (obstacle.shape == ViewObstacle::Shape::kCircle) {
        RequireArgument(out[k - 1] >= 0.0, scene.name, ": view: obstacle '", obstacle.name,
                        "': radius must be >= 0, got ", out[k - 1], " at t0");
      }
    }
  }
  if (!view.window.empty()) {
    const auto& w = view.window;
    RequireArgument(
        w.size() == 4 &&
            std::all_of(w.begin(), w.end(), [](double v) { return std::isfinite(v); }) &&
            w[0] < w[1] && w[2] < w[3],
        scene.name,
        ": view: window must be {xmin, xmax, ymin, ymax} with xmin < xmax and ymin < "
        "ymax (finite)");
  }
}

std::string StateAxisLabel(const SceneView& view, const std::string& name) {
  const auto label = view.labels.find(name);
  const auto unit = view.units.find(name);
  std::string text = label != view.labels.end() ? label->second + " (" + name + ")" : name;
  if (unit != view.units.end() && !unit->second.empty()) text += " [" + unit->second + "]";
  return text;
}

}  // namespace moreau
