#pragma once
/// @file
/// How a scene is shown: names and units of its states (figures) and, for planar scenes, its
/// geometry (animations): which states are the positions of which bodies, their radii, and
/// fixed or moving obstacles given as expressions of t and the parameters.
///
/// A view only describes; it never changes the dynamics. Scene files declare it in a `[view]`
/// section (docs/scene-files.md, docs/visualization.md), built-in scenes in their makers.
/// ValidateScene checks it (ValidateView): unknown state names, negative or non-finite radii,
/// obstacle expressions that do not parse or use names other than t, the parameters, pi and e.

#include <map>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"

namespace moreau {

struct Scene;

/// A body drawn at (x, y) = (state `x`, state `y`): a disc of `radius` (0: a point). A body
/// of a one-dimensional scene leaves `y` empty and moves on the line y = 0.
struct ViewBody {
  /// The body's name (legends, messages).
  std::string name;
  std::string x;        ///< state name of the centre's first coordinate
  std::string y;        ///< state name of the centre's second coordinate, or empty (y = 0)
  double radius = 0.0;  ///< >= 0, in the units of the states
  bool trail = false;   ///< draw the path traced so far (phase planes, single bodies)
};

/// An obstacle whose geometry may move: each coordinate an expression of t and the parameters.
struct ViewObstacle {
  /// The kind of an obstacle.
  enum class Shape {
    kCircle,   ///< expressions: centre x, centre y, radius
    kSegment,  ///< expressions: x1, y1, x2, y2 (a wall, a floor, a moving boundary)
  };
  /// The obstacle's name (legends, messages).
  std::string name;
  /// Circle or segment.
  Shape shape = Shape::kSegment;
  /// The coordinates as expressions of t and the parameters, as many as the shape takes
  /// (NumExpressions).
  std::vector<std::string> expressions;
};
/// "circle", "segment".
std::string ToString(ViewObstacle::Shape shape);
/// Number of expressions a shape takes (circle 3, segment 4).
int NumExpressions(ViewObstacle::Shape shape);

/// The view of a scene (see the file comment). Everything is optional.
struct SceneView {
  /// State name (or "t" for time) -> unit ("m", "V", "°C", "s").
  std::map<std::string, std::string> units;
  /// State name (or "t") -> label ("position").
  std::map<std::string, std::string> labels;
  /// The bodies to draw.
  std::vector<ViewBody> bodies;
  /// The obstacles to draw.
  std::vector<ViewObstacle> obstacles;
  /// Visible region {xmin, xmax, ymin, ymax}, or empty: the bounding box of the bodies' paths
  /// and the obstacles at t0.
  std::vector<double> window;

  /// True if the scene has planar geometry to animate (at least one body).
  bool HasGeometry() const { return !bodies.empty(); }
};

/// Throws std::invalid_argument "<scene>: view: <what>" for: units or labels of unknown states,
/// bodies whose x or y is not a state (naming the closest one), duplicate body names, radii
/// that are negative or not finite, obstacles with the wrong number of expressions or
/// expressions that do not compile over (t, parameters), and a window that is not
/// {xmin < xmax, ymin < ymax} (finite).
void ValidateView(const Scene& scene);

/// The obstacles' geometry as one function of (t, p): outputs are the expressions of every
/// obstacle, in order (x and u are not used). Throws std::invalid_argument as ValidateView.
SmoothFunction ViewObstacleFunction(const Scene& scene);

/// "label [unit]", "label", "name [unit]" or "name": how figures name state `name`.
std::string StateAxisLabel(const SceneView& view, const std::string& name);

}  // namespace moreau
