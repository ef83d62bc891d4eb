#pragma once
// What a frame of a planar scene needs, compiled from its view (moreau/model/view.hpp): the
// bodies' state columns and radii, the obstacles' geometry as one function of (t, p), and the
// view written to and read back from a run directory (view.json), so that `moreau animate`
// draws a run without re-making its scene.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::render {

struct Body {
  std::string name;
  int x = 0;  // state index of the centre's first coordinate
  int y = 0;  // -1: on the line y = 0
  double radius = 0.0;
  bool trail = false;
};

// A circle (cx, cy, r) or a segment (x1, y1, x2, y2) at one time.
struct ObstacleShape {
  ViewObstacle::Shape shape = ViewObstacle::Shape::kSegment;
  double v[4] = {0.0, 0.0, 0.0, 0.0};
};

class CompiledView {
 public:
  // Throws std::invalid_argument if the scene's view is invalid (ValidateView) or has no body.
  explicit CompiledView(const Scene& scene);

  const std::string& scene_name() const { return scene_name_; }
  int num_states() const { return num_states_; }
  double initial_time() const { return t0_; }
  double final_time() const { return tf_; }
  const std::vector<Body>& bodies() const { return bodies_; }
  const std::vector<double>& window() const { return window_; }  // empty: fit to the data
  // The obstacles at time t.
  std::vector<ObstacleShape> Obstacles(double t) const;
  double MaxRadius() const { return max_radius_; }
  // The centre of body b at state x.
  double X(const Body& b, const Vector& x) const { return x[b.x]; }
  double Y(const Body& b, const Vector& x) const { return b.y < 0 ? 0.0 : x[b.y]; }

 private:
  std::string scene_name_;
  int num_states_ = 0;
  double t0_ = 0.0, tf_ = 0.0;
  std::vector<Body> bodies_;
  std::vector<ViewObstacle::Shape> shapes_;
  SmoothFunction geometry_;
  Vector parameters_;
  std::vector<double> window_;
  double max_radius_ = 0.0;
};

// view.json of a run directory: the scene's name, horizon, state names, parameter values (as
// simulated) and its view.
nlohmann::json ViewJson(const Scene& scene);
// The scene of a view.json (no dynamics or effects: enough to draw it and name its states).
// Throws std::invalid_argument naming `source` for a malformed file.
Scene SceneFromViewJson(const nlohmann::json& json, const std::string& source);

}  // namespace moreau::render
