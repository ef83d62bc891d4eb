// moreau._moreau, part 2: what figures and animations need from a scene and a result: the
// scene's view (names, units, planar geometry), its effect functions evaluated on points (set
// boundaries and switching surfaces in phase portraits), the names of the multipliers that are
// the effects' own (not the lowering's internal variables), and animations (render/).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene.hpp"
#include "render/animation.hpp"
#include "render/view_geometry.hpp"

namespace py = pybind11;

namespace moreau::python {

namespace {

const SmoothFunction& EffectFunction(const Scene& scene, const std::string& effect) {
  for (const Effect& e : scene.effects) {
    if (EffectName(e) != effect) continue;
    if (const auto* set = std::get_if<MovingSet>(&e)) return set->constraints;
    if (const auto* sw = std::get_if<SwitchingSurfaces>(&e)) return sw->surfaces;
    if (const auto* dai = std::get_if<PathConstraints>(&e)) return dai->constraints;
    ThrowInvalidArgument("effect '", effect, "' (", EffectKind(e),
                         ") has no constraint or surface function");
  }
  ThrowInvalidArgument("scene '", scene.name, "' has no effect named '", effect, "'");
}

}  // namespace

void BindView(py::module_& m) {
  m.def("_scene_view", [](const Scene& scene) {
    return py::module_::import("json").attr("loads")(render::ViewJson(scene).dump());
  });
  m.def("_multiplier_names", [](const Scene& scene) {
    std::vector<std::string> names;
    for (const Effect& e : scene.effects) {
      std::vector<std::string> parts;
      if (const auto* set = std::get_if<MovingSet>(&e)) parts = set->constraint_names;
      if (const auto* lcs = std::get_if<Complementarity>(&e)) parts = lcs->pair_names;
      for (const std::string& part : parts) names.push_back(EffectName(e) + ".lambda_" + part);
    }
    return names;
  });
  // c(x_k, u(t), t, p) for the rows x_k of X: one row of outputs per point.
  m.def("_effect_values",
        [](const Scene& scene, const std::string& effect, double t, const Matrix& points) {
          const SmoothFunction& f = EffectFunction(scene, effect);
          RequireArgument(points.cols() == scene.num_states(), "points must have ",
                          scene.num_states(), " columns (one per state), got ", points.cols());
          Matrix values(points.rows(), f.num_outputs());
          const Vector p = scene.ParameterValues(), u = scene.InputValues(t);
          Vector out;
          for (Eigen::Index k = 0; k < points.rows(); ++k) {
            f.Evaluate(points.row(k).transpose(), u, t, p, &out);
            values.row(k) = out.transpose();
          }
          return values;
        });
  m.def(
      "_animate",
      [](const Scene& scene, const SimulationResult& result, const std::string& mp4,
         const std::string& gif, const std::string& snapshots, const std::string& frames,
         double fps, double duration, double speed, int width, int gif_width, int max_snapshots) {
        render::AnimationOptions options;
        options.mp4_path = mp4;
        options.gif_path = gif;
        options.snapshot_directory = snapshots;
        options.frame_directory = frames;
        options.fps = fps;
        options.duration = duration;
        options.speed = speed;
        options.width = width;
        options.gif_width = gif_width;
        options.max_snapshots = max_snapshots;
        py::gil_scoped_release release;  // re-acquired when an error unwinds (ValueError)
        const Trajectory& trajectory =
            result.stage_trajectory.size() > 0 ? result.stage_trajectory : result.trajectory;
        const render::AnimationStats stats =
            render::AnimateTrajectory(scene, trajectory, result.final_time, result.events, options);
        return stats.files;
      },
      py::arg("scene"), py::arg("result"), py::arg("mp4"), py::arg("gif"), py::arg("snapshots"),
      py::arg("frames"), py::arg("fps"), py::arg("duration"), py::arg("speed"), py::arg("width"),
      py::arg("gif_width"), py::arg("max_snapshots"));
}

}  // namespace moreau::python
