#include "render/view_geometry.hpp"

#include <algorithm>
#include <unordered_map>

#include "moreau/core/error.hpp"

namespace moreau::render {

CompiledView::CompiledView(const Scene& scene)
    : scene_name_(scene.name),
      num_states_(scene.num_states()),
      t0_(scene.initial_time),
      tf_(scene.final_time),
      parameters_(scene.ParameterValues()),
      window_(scene.view.window) {
  ValidateView(scene);
  RequireArgument(scene.view.HasGeometry(), scene.name,
                  ": nothing to animate: the scene's view declares no bodies (a [view] section "
                  "with [[view.bodies]] in a scene file; docs/visualization.md)");
  std::unordered_map<std::string, int> index;
  for (int i = 0; i < scene.num_states(); ++i) {
    index.emplace(scene.state_names[static_cast<std::size_t>(i)], i);
  }
  for (const ViewBody& body : scene.view.bodies) {
    bodies_.push_back({body.name, index.at(body.x), body.y.empty() ? -1 : index.at(body.y),
                       body.radius, body.trail});
    max_radius_ = std::max(max_radius_, body.radius);
  }
  for (const ViewObstacle& obstacle : scene.view.obstacles) shapes_.push_back(obstacle.shape);
  geometry_ = ViewObstacleFunction(scene);
}

std::vector<ObstacleShape> CompiledView::Obstacles(double t) const {
  std::vector<ObstacleShape> result;
  if (geometry_.empty()) return result;
  Vector values;
  geometry_.Evaluate(Vector(), Vector(), t, parameters_, &values);
  Eigen::Index k = 0;
  for (ViewObstacle::Shape shape : shapes_) {
    ObstacleShape s;
    s.shape = shape;
    for (int i = 0; i < NumExpressions(shape); ++i) s.v[i] = values[k++];
    result.push_back(s);
  }
  return result;
}

nlohmann::json ViewJson(const Scene& scene) {
  nlohmann::json json;
  json["scene"] = scene.name;
  json["t0"] = scene.initial_time;
  json["tf"] = scene.final_time;
  json["states"] = scene.state_names;
  nlohmann::json parameters = nlohmann::json::array();
  for (const ParameterSpec& p : scene.parameters) {
    parameters.push_back({{"name", p.name}, {"value", p.value}});
  }
  json["parameters"] = parameters;
  const SceneView& view = scene.view;
  json["units"] = view.units;
  json["labels"] = view.labels;
  json["window"] = view.window;
  nlohmann::json bodies = nlohmann::json::array();
  for (const ViewBody& b : view.bodies) {
    bodies.push_back(
        {{"name", b.name}, {"x", b.x}, {"y", b.y}, {"radius", b.radius}, {"trail", b.trail}});
  }
  json["bodies"] = bodies;
  nlohmann::json obstacles = nlohmann::json::array();
  for (const ViewObstacle& o : view.obstacles) {
    obstacles.push_back(
        {{"name", o.name}, {"shape", ToString(o.shape)}, {"expressions", o.expressions}});
  }
  json["obstacles"] = obstacles;
  return json;
}

Scene SceneFromViewJson(const nlohmann::json& json, const std::string& source) {
  Scene scene;
  try {
    scene.name = json.at("scene").get<std::string>();
    scene.initial_time = json.at("t0").get<double>();
    scene.final_time = json.at("tf").get<double>();
    scene.state_names = json.at("states").get<std::vector<std::string>>();
    scene.initial_state = Vector::Zero(static_cast<Eigen::Index>(scene.state_names.size()));
    for (const auto& p : json.at("parameters")) {
      scene.AddParameter(p.at("name").get<std::string>(), p.at("value").get<double>(), "");
    }
    SceneView& view = scene.view;
    view.units = json.at("units").get<std::map<std::string, std::string>>();
    view.labels = json.at("labels").get<std::map<std::string, std::string>>();
    view.window = json.at("window").get<std::vector<double>>();
    for (const auto& b : json.at("bodies")) {
      view.bodies.push_back({b.at("name").get<std::string>(), b.at("x").get<std::string>(),
                             b.at("y").get<std::string>(), b.at("radius").get<double>(),
                             b.at("trail").get<bool>()});
    }
    for (const auto& o : json.at("obstacles")) {
      ViewObstacle obstacle;
      obstacle.name = o.at("name").get<std::string>();
      const std::string shape = o.at("shape").get<std::string>();
      RequireArgument(shape == "circle" || shape == "segment", "unknown obstacle shape '", shape,
                      "'");
      obstacle.shape =
          shape == "circle" ? ViewObstacle::Shape::kCircle : ViewObstacle::Shape::kSegment;
      obstacle.expressions = o.at("expressions").get<std::vector<std::string>>();
      view.obstacles.push_back(obstacle);
    }
  } catch (const nlohmann::json::exception& error) {
    ThrowInvalidArgument(source, ": not a view written by `moreau run` (", error.what(), ")");
  }
  ValidateView(scene);
  return scene;
}

}  // namespace moreau::render
