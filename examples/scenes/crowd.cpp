// The crowd-motion scene family (include/moreau/scenes/crowd.hpp, docs/crowd-motion.md).
#include "moreau/scenes/crowd.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <memory>
#include <ostream>
#include <random>
#include <sstream>
#include <system_error>
#include <tuple>

#include "moreau/core/error.hpp"

namespace moreau {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Shortest text that reads back as the same double (std::to_chars), with a decimal point or an
// exponent so that TOML reads it as a float.
std::string Number(double value) {
  std::array<char, 64> buffer{};
  const auto [end, error] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  MOREAU_ASSERT(error == std::errc(), "to_chars failed");
  std::string text(buffer.data(), end);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";  // n: inf, nan
  return text;
}

std::string AgentName(char coordinate, int agent) {
  return std::string(1, coordinate) + std::to_string(agent + 1);
}

// The keys of ParseCrowdOptions, in the order of CrowdSceneName.
struct OptionKey {
  const char* key;
  const char* meaning;
};
constexpr std::array<OptionKey, 11> kOptionKeys = {{
    {"N", "number of agents"},
    {"radius", "disc radius r"},
    {"speed", "desired speed s"},
    {"spacing", "grid spacing a"},
    {"jitter", "jitter fraction"},
    {"seed", "seed of the jitter"},
    {"cutoff", "neighbour-list cutoff"},
    {"door", "door width (0: automatic)"},
    {"exit_distance", "exit point beyond the door"},
    {"smoothing", "smoothing length eps"},
    {"tf", "horizon"},
}};

// The option of key k as text (shortest round trip), for names and generated files.
std::string OptionText(const CrowdOptions& o, std::size_t k) {
  switch (k) {
    case 0:
      return std::to_string(o.agents);
    case 1:
      return Number(o.radius);
    case 2:
      return Number(o.speed);
    case 3:
      return Number(o.spacing);
    case 4:
      return Number(o.jitter);
    case 5:
      return std::to_string(o.seed);
    case 6:
      return Number(o.cutoff);
    case 7:
      return Number(o.door);
    case 8:
      return Number(o.exit_distance);
    case 9:
      return Number(o.smoothing);
    default:
      return Number(o.final_time);
  }
}

// "N=16,seed=3": the options that differ from the defaults.
std::string NonDefaultOptions(const CrowdOptions& options, const char* separator, bool equals) {
  const CrowdOptions defaults;
  std::string text;
  for (std::size_t k = 0; k < kOptionKeys.size(); ++k) {
    const std::string value = OptionText(options, k);
    if (value == OptionText(defaults, k)) continue;
    if (!text.empty()) text += separator;
    text += std::string(kOptionKeys[k].key) + (equals ? "=" : "") + value;
  }
  return text;
}

// The model data shared by the scene's functions (copies of a SmoothFunction share it).
struct CrowdModel {
  // Pair constraints: (|q_i - q_j|^2 - d2) * pair_scale.
  std::vector<std::pair<int, int>> pairs;
  double d2 = 0.0;
  double pair_scale = 0.0;
  // Wall constraints.
  std::vector<CrowdWallConstraint> walls;
  double radius = 0.0;
  double wall_offset = 0.0;  // H/2 - r: bottom y + offset, top offset - y
  double jamb_x = 0.0, jamb_y = 0.0;
  double jamb_d2 = 0.0;  // (R + r)^2
  double jamb_scale = 0.0;
};

// Columns ceil(sqrt N) and rows ceil(N / columns) of the start grid.
std::pair<int, int> GridShape(int agents) {
  const int columns = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(agents))));
  return {columns, (agents + columns - 1) / columns};
}

// The parameters of every crowd scene, in this order.
enum Parameter { kSpeed = 0, kSmoothing = 1, kExitX = 2, kExitY = 3 };

}  // namespace

std::string ToString(CrowdWall wall) {
  switch (wall) {
    case CrowdWall::kLeft:
      return "left";
    case CrowdWall::kBottom:
      return "bottom";
    case CrowdWall::kTop:
      return "top";
    case CrowdWall::kUpperJamb:
      return "upper_jamb";
    case CrowdWall::kLowerJamb:
      return "lower_jamb";
  }
  return "unknown";
}

void CrowdOptions::Validate() const {
  auto finite_positive = [](double value) { return std::isfinite(value) && value > 0.0; };
  RequireArgument(agents >= 1 && agents <= kMaxCrowdAgents,
                  "crowd option N (agents) must be in [1, ", kMaxCrowdAgents, "], got ", agents);
  RequireArgument(finite_positive(radius), "crowd option radius must be finite and > 0, got ",
                  radius);
  RequireArgument(finite_positive(speed), "crowd option speed must be finite and > 0, got ", speed);
  RequireArgument(std::isfinite(spacing) && spacing > 2.0 * radius,
                  "crowd option spacing must be finite and > 2 radius = ", 2.0 * radius,
                  " (discs may not overlap at the start), got ", spacing);
  RequireArgument(std::isfinite(jitter) && jitter >= 0.0 && jitter < 1.0,
                  "crowd option jitter must be in [0, 1), got ", jitter);
  RequireArgument(std::isfinite(cutoff) && cutoff > 2.0 * radius,
                  "crowd option cutoff must be finite and > 2 radius = ", 2.0 * radius, ", got ",
                  cutoff);
  RequireArgument(std::isfinite(door) && door >= 0.0,
                  "crowd option door must be finite and >= 0 (0: automatic), got ", door);
  RequireArgument(std::isfinite(exit_distance) && exit_distance >= 0.0,
                  "crowd option exit_distance must be finite and >= 0, got ", exit_distance);
  RequireArgument(finite_positive(smoothing), "crowd option smoothing must be finite and > 0, got ",
                  smoothing);
  RequireArgument(finite_positive(final_time), "crowd option tf must be finite and > 0, got ",
                  final_time);
  const double height = GridShape(agents).second * spacing;
  RequireArgument(door < height, "crowd option door must be below the room height H = ", height,
                  " (rows times spacing), got ", door);
}

double CrowdLayout::WallGap(const ConstVectorRef& q, int agent, CrowdWall wall) const {
  const double x = q[2 * agent], y = q[2 * agent + 1], r = options.radius;
  switch (wall) {
    case CrowdWall::kLeft:
      return x - r;
    case CrowdWall::kBottom:
      return y + 0.5 * room_height - r;
    case CrowdWall::kTop:
      return 0.5 * room_height - y - r;
    case CrowdWall::kUpperJamb:
      return std::hypot(x - door_x, y - upper_jamb_y) - jamb_radius - r;
    case CrowdWall::kLowerJamb:
      return std::hypot(x - door_x, y + upper_jamb_y) - jamb_radius - r;
  }
  return kInfinity;
}

std::vector<std::pair<int, int>> FindCrowdPairs(const ConstVectorRef& q, double distance) {
  RequireArgument(q.size() % 2 == 0, "crowd positions must have 2 entries per agent, got ",
                  q.size(), " entries");
  RequireArgument(std::isfinite(distance) && distance > 0.0,
                  "pair search distance must be finite and > 0, got ", distance);
  RequireArgument(q.allFinite(), "crowd positions must be finite");
  const int n = static_cast<int>(q.size() / 2);
  std::vector<std::pair<int, int>> pairs;
  if (n < 2) return pairs;
  double x_min = kInfinity, y_min = kInfinity, x_max = -kInfinity, y_max = -kInfinity;
  for (int i = 0; i < n; ++i) {
    x_min = std::min(x_min, q[2 * i]);
    x_max = std::max(x_max, q[2 * i]);
    y_min = std::min(y_min, q[2 * i + 1]);
    y_max = std::max(y_max, q[2 * i + 1]);
  }
  // Cells of size >= distance, so that every pair closer than `distance` lies in neighbouring
  // cells; at most about 4 cells per agent (agents spread over a large box get larger cells).
  double cell = distance;
  const double max_cells = 4.0 * n + 64.0;
  const double wanted = ((x_max - x_min) / cell + 1.0) * ((y_max - y_min) / cell + 1.0);
  if (wanted > max_cells) cell *= std::sqrt(wanted / max_cells);
  const int nx = static_cast<int>((x_max - x_min) / cell) + 1;
  const int ny = static_cast<int>((y_max - y_min) / cell) + 1;
  auto cell_x = [&](int i) {
    return std::min(nx - 1, static_cast<int>((q[2 * i] - x_min) / cell));
  };
  auto cell_y = [&](int i) {
    return std::min(ny - 1, static_cast<int>((q[2 * i + 1] - y_min) / cell));
  };
  // Counting sort of the agents by cell (compressed rows: start[c] .. start[c + 1]).
  std::vector<int> start(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny) + 1, 0);
  std::vector<int> cell_of(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    cell_of[static_cast<std::size_t>(i)] = cell_y(i) * nx + cell_x(i);
    ++start[static_cast<std::size_t>(cell_of[static_cast<std::size_t>(i)]) + 1];
  }
  for (std::size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  std::vector<int> agents(static_cast<std::size_t>(n));
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int i = 0; i < n; ++i) {
    agents[static_cast<std::size_t>(
        fill[static_cast<std::size_t>(cell_of[static_cast<std::size_t>(i)])]++)] = i;
  }
  const double distance2 = distance * distance;
  for (int i = 0; i < n; ++i) {
    const int cx = cell_x(i), cy = cell_y(i);
    for (int gy = std::max(0, cy - 1); gy <= std::min(ny - 1, cy + 1); ++gy) {
      for (int gx = std::max(0, cx - 1); gx <= std::min(nx - 1, cx + 1); ++gx) {
        const std::size_t c = static_cast<std::size_t>(gy * nx + gx);
        for (int k = start[c]; k < start[c + 1]; ++k) {
          const int j = agents[static_cast<std::size_t>(k)];
          if (j <= i) continue;
          const double dx = q[2 * i] - q[2 * j], dy = q[2 * i + 1] - q[2 * j + 1];
          if (dx * dx + dy * dy < distance2) pairs.emplace_back(i, j);
        }
      }
    }
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

namespace {

// The neighbour list (pairs closer than the cutoff) and the wall list (the jambs for every
// agent, a straight wall for the agents closer to it than the pairs' gap threshold) of the
// layout's initial state.
void BuildLists(CrowdLayout* layout) {
  const CrowdOptions& options = layout->options;
  layout->pairs = FindCrowdPairs(layout->initial_state, options.cutoff);
  layout->walls.clear();
  const double wall_cutoff = options.cutoff - 2.0 * options.radius;
  for (int i = 0; i < options.agents; ++i) {
    for (CrowdWall wall : {CrowdWall::kLeft, CrowdWall::kBottom, CrowdWall::kTop}) {
      if (layout->WallGap(layout->initial_state, i, wall) < wall_cutoff) {
        layout->walls.push_back({i, wall});
      }
    }
    layout->walls.push_back({i, CrowdWall::kUpperJamb});
    layout->walls.push_back({i, CrowdWall::kLowerJamb});
  }
}

}  // namespace

CrowdLayout MakeCrowdLayout(const CrowdOptions& options) {
  options.Validate();
  CrowdLayout layout;
  layout.options = options;
  const int n = options.agents;
  const double r = options.radius, a = options.spacing;
  std::tie(layout.columns, layout.rows) = GridShape(n);
  layout.grid_length = layout.columns * a;
  layout.room_height = layout.rows * a;
  const double h = layout.room_height;
  layout.door_width = options.door > 0.0 ? options.door : std::min(6.0 * r, 0.5 * h);
  layout.jamb_radius = 0.5 * h;
  // The jambs lie in x >= L - R = L0 + a/2, and every agent starts at x <= L0 - a/2 + j: at a gap
  // of at least a - r - j from them, more than from the straight walls.
  layout.door_x = layout.grid_length + 0.5 * a + layout.jamb_radius;
  layout.upper_jamb_y = 0.5 * layout.door_width + layout.jamb_radius;
  layout.exit_x = layout.door_x + options.exit_distance;

  // Jittered grid, row by row from the bottom, left to right.
  std::mt19937_64 engine(options.seed);
  const double amplitude = options.jitter * 0.5 * (a - 2.0 * r);
  std::uniform_real_distribution<double> jitter(-amplitude, amplitude);
  layout.initial_state.resize(2 * static_cast<Eigen::Index>(n));
  for (int i = 0; i < n; ++i) {
    const int column = i % layout.columns, row = i / layout.columns;
    const double dx = jitter(engine), dy = jitter(engine);
    layout.initial_state[2 * i] = (column + 0.5) * a + dx;
    layout.initial_state[2 * i + 1] = (row + 0.5) * a - 0.5 * h + dy;
  }

  BuildLists(&layout);
  return layout;
}

CrowdLayout RelistCrowdLayout(const CrowdLayout& layout, const ConstVectorRef& q) {
  RequireArgument(q.size() == 2 * static_cast<Eigen::Index>(layout.num_agents()),
                  "crowd state must have 2N = ", 2 * layout.num_agents(), " entries, got ",
                  q.size());
  RequireArgument(q.allFinite(), "crowd state must be finite");
  CrowdLayout relisted = layout;
  relisted.initial_state = q;
  BuildLists(&relisted);
  return relisted;
}

namespace {

// The agents as discs, the room's walls as segments and the jambs as discs; the window shows
// the room and the corridor behind the door.
void AddCrowdView(const CrowdLayout& layout, Scene* scene) {
  const double r = layout.options.radius;
  const int n = layout.options.agents;
  SceneView& view = scene->view;
  view.bodies.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    view.bodies.push_back(
        {"agent_" + std::to_string(i + 1), AgentName('x', i), AgentName('y', i), r, false});
  }
  const std::string half = Number(0.5 * layout.room_height);
  const std::string door = Number(layout.door_x);
  const std::string jamb_y = Number(layout.upper_jamb_y);
  const std::string jamb_r = Number(layout.jamb_radius);
  using Shape = ViewObstacle::Shape;
  view.obstacles = {{"left", Shape::kSegment, {"0", "-" + half, "0", half}},
                    {"bottom", Shape::kSegment, {"0", "-" + half, door, "-" + half}},
                    {"top", Shape::kSegment, {"0", half, door, half}},
                    {"upper_jamb", Shape::kCircle, {door, jamb_y, jamb_r}},
                    {"lower_jamb", Shape::kCircle, {door, "-" + jamb_y, jamb_r}}};
  const double margin = 2.0 * r;
  view.window = {-margin, layout.door_x + 0.5 * layout.room_height,
                 -0.5 * layout.room_height - margin, 0.5 * layout.room_height + margin};
}

}  // namespace

Scene MakeCrowdScene(const CrowdLayout& layout) {
  const CrowdOptions& o = layout.options;
  const int n = o.agents;
  const double r = o.radius;
  Scene scene;
  scene.name = CrowdSceneName(o);
  scene.description = internal::Concat(
      "crowd motion (Maury & Venel 2011): ", n, " discs of radius ", Number(r),
      " walk toward the exit point (", Number(layout.exit_x), ", 0) at speed ", Number(o.speed),
      " through a door of width ", Number(layout.door_width), " between two jambs of radius ",
      Number(layout.jamb_radius), "; ", layout.pairs.size(),
      " non-overlap constraints (pairs closer than ", Number(o.cutoff), " at t = 0), ",
      layout.walls.size(), " wall constraints (docs/crowd-motion.md)");
  scene.state_names.reserve(2 * static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    scene.state_names.push_back(AgentName('x', i));
    scene.state_names.push_back(AgentName('y', i));
  }
  scene.initial_state = layout.initial_state;
  scene.final_time = o.final_time;
  scene.AddParameter("speed", o.speed, "desired speed s");
  scene.AddParameter("smoothing", o.smoothing,
                     "smoothing length eps of the desired velocity s (e - q) / sqrt(|e - q|^2 + "
                     "eps^2)");
  scene.AddParameter("exit_x", layout.exit_x, "exit point e, x");
  scene.AddParameter("exit_y", 0.0, "exit point e, y");
  AddCrowdView(layout, &scene);

  // One block per agent (its velocity reads its two coordinates: a 2 x 2 block diagonal
  // Jacobian), one per pair and one per wall constraint: sparse derivatives evaluate only the
  // blocks of the constraints in an element system (MakeBlockFunction).
  scene.dynamics = MakeBlockFunction(
      "crowd.desired_velocity", n, 2,
      [](int i, const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        using std::sqrt;
        const auto dx = p[kExitX] - x[2 * i];
        const auto dy = p[kExitY] - x[2 * i + 1];
        const auto norm = sqrt(dx * dx + dy * dy + p[kSmoothing] * p[kSmoothing]);
        out[0] = p[kSpeed] * dx / norm;
        out[1] = p[kSpeed] * dy / norm;
      });

  auto model = std::make_shared<CrowdModel>();
  model->pairs = layout.pairs;
  model->d2 = 4.0 * r * r;
  model->pair_scale = 1.0 / (4.0 * r);
  model->walls = layout.walls;
  model->radius = r;
  model->wall_offset = 0.5 * layout.room_height - r;
  model->jamb_x = layout.door_x;
  model->jamb_y = layout.upper_jamb_y;
  model->jamb_d2 = (layout.jamb_radius + r) * (layout.jamb_radius + r);
  model->jamb_scale = 1.0 / (2.0 * (layout.jamb_radius + r));
  std::shared_ptr<const CrowdModel> shared = model;

  if (!layout.pairs.empty()) {
    MovingSet contacts;
    contacts.name = "contacts";
    contacts.constraint_names.reserve(layout.pairs.size());
    for (const auto& [i, j] : layout.pairs) {
      contacts.constraint_names.push_back("pair_" + std::to_string(i + 1) + "_" +
                                          std::to_string(j + 1));
    }
    contacts.constraints = MakeBlockFunction(
        "crowd.contacts", static_cast<int>(layout.pairs.size()), 1,
        [shared](int k, const auto& x, const auto&, const auto&, const auto&, auto& out) {
          const CrowdModel& m = *shared;
          const int i = m.pairs[static_cast<std::size_t>(k)].first;
          const int j = m.pairs[static_cast<std::size_t>(k)].second;
          const auto dx = x[2 * i] - x[2 * j];
          const auto dy = x[2 * i + 1] - x[2 * j + 1];
          out[0] = (dx * dx + dy * dy - m.d2) * m.pair_scale;
        });
    scene.effects.push_back(std::move(contacts));
  }

  MovingSet walls;
  walls.name = "walls";
  walls.constraint_names.reserve(layout.walls.size());
  for (const CrowdWallConstraint& w : layout.walls) {
    walls.constraint_names.push_back(ToString(w.wall) + "_" + std::to_string(w.agent + 1));
  }
  walls.constraints = MakeBlockFunction(
      "crowd.walls", static_cast<int>(layout.walls.size()), 1,
      [shared](int k, const auto& x, const auto&, const auto&, const auto&, auto& out) {
        const CrowdModel& m = *shared;
        const CrowdWallConstraint& w = m.walls[static_cast<std::size_t>(k)];
        const int i = w.agent;
        // The branch is on the constraint's kind (a constant), never on a traced value.
        switch (w.wall) {
          case CrowdWall::kLeft:
            out[0] = x[2 * i] - m.radius;
            break;
          case CrowdWall::kBottom:
            out[0] = x[2 * i + 1] + m.wall_offset;
            break;
          case CrowdWall::kTop:
            out[0] = m.wall_offset - x[2 * i + 1];
            break;
          case CrowdWall::kUpperJamb:
          case CrowdWall::kLowerJamb: {
            const double centre_y = w.wall == CrowdWall::kUpperJamb ? m.jamb_y : -m.jamb_y;
            const auto dx = x[2 * i] - m.jamb_x;
            const auto dy = x[2 * i + 1] - centre_y;
            out[0] = (dx * dx + dy * dy - m.jamb_d2) * m.jamb_scale;
            break;
          }
        }
      });
  scene.effects.push_back(std::move(walls));
  return scene;
}

Scene MakeCrowdScene(const CrowdOptions& options) {
  return MakeCrowdScene(MakeCrowdLayout(options));
}

bool CrowdCertificate::Feasible(double tolerance) const {
  return min_pair_gap >= -tolerance && min_wall_gap >= -tolerance;
}

std::string CrowdCertificate::Summary() const {
  std::ostringstream text;
  text.precision(6);
  text << "min pair gap " << min_pair_gap;
  if (pair_i >= 0) text << " (agents " << pair_i + 1 << ", " << pair_j + 1 << ")";
  text << ", min unlisted pair gap " << min_unlisted_pair_gap;
  if (unlisted_i >= 0) text << " (agents " << unlisted_i + 1 << ", " << unlisted_j + 1 << ")";
  text << ", min wall gap " << min_wall_gap;
  if (wall_agent >= 0) text << " (agent " << wall_agent + 1 << ", " << ToString(wall) << ")";
  text << ", min unlisted wall gap " << min_unlisted_wall_gap;
  return text.str();
}

CrowdCertificate CertifyCrowdState(const CrowdLayout& layout, const ConstVectorRef& q) {
  const int n = layout.num_agents();
  RequireArgument(q.size() == 2 * static_cast<Eigen::Index>(n),
                  "crowd state must have 2N = ", 2 * n, " entries, got ", q.size());
  RequireArgument(q.allFinite(), "crowd state must be finite");
  const double r = layout.options.radius;
  CrowdCertificate certificate;
  certificate.min_pair_gap = kInfinity;
  certificate.min_unlisted_pair_gap = kInfinity;
  // Pairs farther apart than 4r have gaps above 2r and decide no minimum that matters.
  for (const auto& [i, j] : FindCrowdPairs(q, 4.0 * r)) {
    const double gap = std::hypot(q[2 * i] - q[2 * j], q[2 * i + 1] - q[2 * j + 1]) - 2.0 * r;
    if (gap < certificate.min_pair_gap) {
      certificate.min_pair_gap = gap;
      certificate.pair_i = i;
      certificate.pair_j = j;
    }
    if (gap < certificate.min_unlisted_pair_gap &&
        !std::binary_search(layout.pairs.begin(), layout.pairs.end(), std::make_pair(i, j))) {
      certificate.min_unlisted_pair_gap = gap;
      certificate.unlisted_i = i;
      certificate.unlisted_j = j;
    }
  }
  certificate.min_wall_gap = kInfinity;
  certificate.min_unlisted_wall_gap = kInfinity;
  std::size_t next = 0;  // layout.walls is sorted by agent, in the order of the loop below
  for (int i = 0; i < n; ++i) {
    for (CrowdWall wall : {CrowdWall::kLeft, CrowdWall::kBottom, CrowdWall::kTop,
                           CrowdWall::kUpperJamb, CrowdWall::kLowerJamb}) {
      const double gap = layout.WallGap(q, i, wall);
      if (gap < certificate.min_wall_gap) {
        certificate.min_wall_gap = gap;
        certificate.wall_agent = i;
        certificate.wall = wall;
      }
      const bool listed = next < layout.walls.size() && layout.walls[next].agent == i &&
                          layout.walls[next].wall == wall;
      if (listed) {
        ++next;
      } else {
        certificate.min_unlisted_wall_gap = std::min(certificate.min_unlisted_wall_gap, gap);
      }
    }
  }
  MOREAU_ASSERT(next == layout.walls.size(), "crowd wall list out of order");
  return certificate;
}

CrowdOptions ParseCrowdOptions(const std::string& text) {
  CrowdOptions options;
  std::vector<bool> seen(kOptionKeys.size(), false);
  std::string valid;
  for (const OptionKey& key : kOptionKeys) {
    valid += (valid.empty() ? "" : ", ") + std::string(key.key) + " (" + key.meaning + ")";
  }
  // Comma-separated items; an empty text has none, "N=4," has an empty second one.
  for (std::size_t position = 0; !text.empty() && position <= text.size();) {
    const std::size_t comma = std::min(text.find(',', position), text.size());
    const std::string item = text.substr(position, comma - position);
    position = comma + 1;
    const std::size_t equals = item.find('=');
    RequireArgument(equals != std::string::npos && equals > 0, "bad crowd option '", item,
                    "': expected key=value (keys: ", valid, ")");
    const std::string key = item.substr(0, equals), value = item.substr(equals + 1);
    std::size_t k = 0;
    while (k < kOptionKeys.size() && key != kOptionKeys[k].key) ++k;
    RequireArgument(k < kOptionKeys.size(), "unknown crowd option '", key,
                    "'; valid keys: ", valid);
    RequireArgument(!seen[k], "crowd option '", key, "' given twice");
    seen[k] = true;
    if (k == 5) {  // seed: an unsigned 64-bit integer
      std::uint64_t seed = 0;
      const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), seed);
      RequireArgument(error == std::errc() && end == value.data() + value.size() && !value.empty(),
                      "bad value '", value, "' for crowd option seed: expected an integer in [0, ",
                      std::numeric_limits<std::uint64_t>::max(), "]");
      options.seed = seed;
      continue;
    }
    double number = 0.0;
    const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), number);
    RequireArgument(error == std::errc() && end == value.data() + value.size() && !value.empty(),
                    "bad value '", value, "' for crowd option ", key, ": expected a number");
    switch (k) {
      case 0:
        RequireArgument(number == std::floor(number) && number >= 1.0 && number <= kMaxCrowdAgents,
                        "bad value '", value, "' for crowd option N: expected an integer in [1, ",
                        kMaxCrowdAgents, "]");
        options.agents = static_cast<int>(number);
        break;
      case 1:
        options.radius = number;
        break;
      case 2:
        options.speed = number;
        break;
      case 3:
        options.spacing = number;
        break;
      case 4:
        options.jitter = number;
        break;
      case 6:
        options.cutoff = number;
        break;
      case 7:
        options.door = number;
        break;
      case 8:
        options.exit_distance = number;
        break;
      case 9:
        options.smoothing = number;
        break;
      default:
        options.final_time = number;
        break;
    }
  }
  options.Validate();
  return options;
}

std::string CrowdSceneName(const CrowdOptions& options) {
  const std::string suffix = NonDefaultOptions(options, "_", false);
  return suffix.empty() ? "crowd" : "crowd_" + suffix;
}

void WriteCrowdSceneFile(const CrowdOptions& options, std::ostream& out) {
  const CrowdLayout layout = MakeCrowdLayout(options);
  const Scene scene = MakeCrowdScene(layout);
  const int n = options.agents;
  const double r = options.radius;
  // A TOML array of strings, `per_line` items on each line.
  auto strings = [&out](const std::vector<std::string>& items, std::size_t per_line) {
    out << "[";
    for (std::size_t k = 0; k < items.size(); ++k) {
      out << (k == 0 ? "\n  " : k % per_line == 0 ? ",\n  " : ", ") << '"' << items[k] << '"';
    }
    out << "\n]\n";
  };
  const std::string generated = NonDefaultOptions(options, " ", true);
  out << "# Crowd motion (Maury & Venel 2011), generated by `moreau crowd-file"
      << (generated.empty() ? "" : " ") << generated
      << "`\n# (WriteCrowdSceneFile; docs/crowd-motion.md). The same scene as the built-in '"
      << (generated.empty() ? std::string("crowd")
                            : "crowd:" + NonDefaultOptions(options, ",", true))
      << "'.\n";
  out << "name = \"" << scene.name << "\"\n";
  out << "description = \"" << scene.description << "\"\n";
  out << "states = ";
  strings(scene.state_names, 8);
  out << "x0 = [";
  for (Eigen::Index k = 0; k < scene.initial_state.size(); ++k) {
    out << (k % 2 == 0 ? (k ? ",\n  " : "\n  ") : ", ") << Number(scene.initial_state[k]);
  }
  out << "\n]\n";
  out << "tf = " << Number(scene.final_time) << "\n";
  // The operations and their order are those of the compiled lambdas (MakeCrowdScene), so
  // that the interpreter computes the same values to the last bit.
  std::vector<std::string> dynamics;
  for (int i = 0; i < n; ++i) {
    const std::string x = AgentName('x', i), y = AgentName('y', i);
    const std::string norm = "sqrt((exit_x - " + x + ")^2 + (exit_y - " + y + ")^2 + smoothing^2)";
    dynamics.push_back("speed*(exit_x - " + x + ")/" + norm);
    dynamics.push_back("speed*(exit_y - " + y + ")/" + norm);
  }
  out << "dynamics = ";
  strings(dynamics, 1);
  for (const ParameterSpec& parameter : scene.parameters) {
    out << "\n[[parameters]]\nname = \"" << parameter.name
        << "\"\nvalue = " << Number(parameter.value) << "\ndescription = \""
        << parameter.description << "\"\n";
  }
  const std::string d2 = Number(4.0 * r * r), pair_scale = Number(1.0 / (4.0 * r));
  for (const Effect& effect : scene.effects) {
    const MovingSet& set = std::get<MovingSet>(effect);
    out << "\n[[effects]]\nkind = \"moving_set\"\nname = \"" << set.name << "\"\n";
    out << "constraint_names = ";
    strings(set.constraint_names, 6);
    std::vector<std::string> constraints;
    if (set.name == "contacts") {
      for (const auto& [i, j] : layout.pairs) {
        constraints.push_back("((" + AgentName('x', i) + " - " + AgentName('x', j) + ")^2 + (" +
                              AgentName('y', i) + " - " + AgentName('y', j) + ")^2 - " + d2 + ")*" +
                              pair_scale);
      }
    } else {
      const std::string offset = Number(0.5 * layout.room_height - r);
      const double jamb_r = layout.jamb_radius + r;
      const std::string jamb_x = Number(layout.door_x), jamb_y = Number(layout.upper_jamb_y),
                        jamb_d2 = Number(jamb_r * jamb_r),
                        jamb_scale = Number(1.0 / (2.0 * jamb_r));
      for (const CrowdWallConstraint& w : layout.walls) {
        const std::string x = AgentName('x', w.agent), y = AgentName('y', w.agent);
        switch (w.wall) {
          case CrowdWall::kLeft:
            constraints.push_back(x + " - " + Number(r));
            break;
          case CrowdWall::kBottom:
            constraints.push_back(y + " + " + offset);
            break;
          case CrowdWall::kTop:
            constraints.push_back(offset + " - " + y);
            break;
          case CrowdWall::kUpperJamb:
          case CrowdWall::kLowerJamb:
            // y - (-c) and y + c are the same IEEE operation.
            constraints.push_back("((" + x + " - " + jamb_x + ")^2 + (" + y +
                                  (w.wall == CrowdWall::kUpperJamb ? " - " : " + ") + jamb_y +
                                  ")^2 - " + jamb_d2 + ")*" + jamb_scale);
            break;
        }
      }
    }
    out << "constraints = ";
    strings(constraints, 1);
  }
  // The view: agents as discs, walls and jambs as obstacles (docs/visualization.md).
  const SceneView& view = scene.view;
  out << "\n[view]\nwindow = [" << Number(view.window[0]) << ", " << Number(view.window[1]) << ", "
      << Number(view.window[2]) << ", " << Number(view.window[3]) << "]\n";
  for (const ViewBody& body : view.bodies) {
    out << "\n[[view.bodies]]\nname = \"" << body.name << "\"\nx = \"" << body.x << "\"\ny = \""
        << body.y << "\"\nradius = " << Number(body.radius) << "\n";
  }
  for (const ViewObstacle& obstacle : view.obstacles) {
    const auto& e = obstacle.expressions;
    out << "\n[[view.obstacles]]\nname = \"" << obstacle.name << "\"\n";
    if (obstacle.shape == ViewObstacle::Shape::kCircle) {
      out << "shape = \"circle\"\ncenter = [\"" << e[0] << "\", \"" << e[1] << "\"]\nradius = \""
          << e[2] << "\"\n";
    } else {
      out << "shape = \"segment\"\nfrom = [\"" << e[0] << "\", \"" << e[1] << "\"]\nto = [\""
          << e[2] << "\", \"" << e[3] << "\"]\n";
    }
  }
}

}  // namespace moreau
