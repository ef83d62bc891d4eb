#pragma once
/// @file
/// The crowd-motion scene family (docs/crowd-motion.md): N discs of radius r in the plane,
/// pushed toward an exit by a smoothed desired velocity, that may not overlap each other, the
/// walls of their room or the two jambs of its door. The first-order contact model of
/// B. Maury and J. Venel, "A discrete contact model for crowd motion", ESAIM: M2AN 45(1),
/// 145-168, 2011: the actual velocity is the projection of the desired one on the admissible
/// velocities, i.e. the sweeping process q' in U(q) - N_C(q).
///
/// States q = (x_1, y_1, ..., x_N, y_N) (names x1, y1, ...). Geometry (r the radius, a the
/// grid spacing): agents start on a jittered grid of ceil(sqrt N) columns filled row by row
/// in the rectangle [0, L0] x [-H/2, H/2] (L0 = columns a, H = rows a); the room is closed
/// by the half-planes x >= 0 (left wall) and |y| <= H/2 (bottom and top walls) and, on the
/// right, by two jambs: discs of radius R = H/2 centred at (L, +-(w/2 + R)), L = L0 + a/2 + R,
/// between which the door of width w opens at x = L. The exit point e = (L + exit_distance, 0)
/// lies beyond the door. Every constraint is a polynomial of degree <= 2 (C^infinity, constant
/// Hessian); the desired velocity U(q_i) = s (e - q_i) / sqrt(|e - q_i|^2 + eps^2) is smooth.
///
/// Two MovingSet effects (each constraint reads the coordinates of at most two agents):
///  - "contacts": c_ij = (|q_i - q_j|^2 - (2r)^2) / (4r) >= 0 for every pair (i, j) of the
///    fixed neighbour list (initial centre distance below `cutoff`). The scaling makes the
///    gradient with respect to q_i a unit vector at contact and c_ij = gap (1 + gap / (4r))
///    for the gap |q_i - q_j| - 2r, so that constraint values read as distances;
///  - "walls": the jambs (|q_i - p|^2 - (R + r)^2) / (2 (R + r)) >= 0 for every agent, the
///    straight walls (x_i - r >= 0, y_i + H/2 - r >= 0, H/2 - r - y_i >= 0) for the agents
///    whose initial gap to that wall is below cutoff - 2r (the others start behind other
///    agents and are pushed away from the walls, toward e).
/// The neighbour list is fixed: CertifyCrowdState checks a state against every pair and every
/// wall (cell grid, O(N)), so that a simulation can assert that the list sufficed.

#include <cstdint>
#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

#include "moreau/model/scene.hpp"

namespace moreau {

/// Options of a crowd scene (see the file comment; lengths in the units of the radius).
struct CrowdOptions {
  /// Number of agents N in [1, kMaxCrowdAgents]: 2N states.
  int agents = 100;
  /// Disc radius r > 0.
  double radius = 0.5;
  /// Desired speed s > 0 (scene parameter `speed`).
  double speed = 1.0;
  /// Centre distance a of grid neighbours at the start, > 2 radius.
  double spacing = 1.25;
  /// Jitter of the start, in [0, 1): each coordinate moves by a uniform amount in
  /// [-j, j], j = jitter (spacing - 2 radius) / 2. Every pair then starts at a gap of at least
  /// (1 - jitter)(spacing - 2 radius) and every agent at least (1 - jitter)(spacing/2 - radius)
  /// from the walls.
  double jitter = 0.4;
  /// Seed of the jitter (std::mt19937_64): the same options give the same scene everywhere.
  std::uint64_t seed = 1;
  /// Neighbour-list cutoff, > 2 radius: a pair gets a non-overlap constraint if its initial
  /// centre distance is below the cutoff, an agent a straight-wall constraint if its initial
  /// gap to the wall is below cutoff - 2 radius. The default keeps the 20 nearest grid
  /// neighbours (distances a, a sqrt 2, 2a, a sqrt 5, jittered to at most 2.94; the next shell,
  /// a sqrt 8, starts at 3.39): in the default horizon no other pair came near contact
  /// (docs/crowd-motion.md, measured with examples/crowd_catchup); CertifyCrowdState checks a
  /// simulation's states.
  double cutoff = 3.25;
  /// Width w of the door, in (0, H); 0: min(6 radius, H / 2) (three agents abreast, at most
  /// half the room height).
  double door = 0.0;
  /// Distance >= 0 of the exit point e beyond the door line. The default puts e far down the
  /// corridor behind the door: agents that pass the door walk on instead of piling up at e.
  double exit_distance = 50.0;
  /// Smoothing length eps > 0 of the desired velocity (scene parameter `smoothing`): the speed
  /// is s d / sqrt(d^2 + eps^2) at distance d from e.
  double smoothing = 1.0;
  /// Horizon tf > 0. By the default tf = 4.5 about 45 of 100 agents are in contact, and among
  /// 10^4 agents more than 200 contacts are active, while every pair outside the neighbour list
  /// is still at least 0.36 (about 0.7 r) from contact (docs/crowd-motion.md). Longer horizons:
  /// a larger cutoff, or segments with RelistCrowdLayout.
  double final_time = 4.5;

  /// Throws std::invalid_argument naming the first out-of-range option ("what, expected, got").
  void Validate() const;
};

/// Most agents a crowd scene may have (a scene holds about 1 kB per agent: lists and names).
inline constexpr int kMaxCrowdAgents = 1'000'000;

/// A wall of the crowd's room (see the file comment).
enum class CrowdWall { kLeft, kBottom, kTop, kUpperJamb, kLowerJamb };
/// "left", "bottom", "top", "upper_jamb", "lower_jamb".
std::string ToString(CrowdWall wall);

/// One wall constraint: agent (0-based) and wall.
struct CrowdWallConstraint {
  /// The agent (0-based).
  int agent = 0;
  /// The wall.
  CrowdWall wall = CrowdWall::kLeft;
};

/// The geometry, start and constraint lists of a crowd scene, computed from its options.
struct CrowdLayout {
  CrowdOptions options;       ///< the options it was made from
  int columns = 0;            ///< grid columns ceil(sqrt N)
  int rows = 0;               ///< grid rows ceil(N / columns)
  double grid_length = 0.0;   ///< L0 = columns a: the start region is x in [0, L0]
  double room_height = 0.0;   ///< H = rows a: the room is |y| <= H/2
  double door_x = 0.0;        ///< L = L0 + a/2 + R: the door line, the jambs' centres' x
  double door_width = 0.0;    ///< w
  double jamb_radius = 0.0;   ///< R = H/2
  double upper_jamb_y = 0.0;  ///< w/2 + R (the lower jamb is centred at -upper_jamb_y)
  double exit_x = 0.0;        ///< e = (exit_x, 0), exit_x = L + exit_distance
  Vector initial_state;       ///< (x_1, y_1, ..., x_N, y_N)
  /// Neighbour list: pairs (i, j), i < j (0-based agents), sorted, whose initial centre
  /// distance is below the cutoff. Constraint k of the "contacts" effect is pairs[k].
  std::vector<std::pair<int, int>> pairs;
  /// Constraint k of the "walls" effect, sorted by agent.
  std::vector<CrowdWallConstraint> walls;

  /// Number of agents N.
  int num_agents() const { return options.agents; }
  /// Gap between agent i's disc and a wall at state q: the distance of its centre to the
  /// wall (line or jamb disc) minus r; negative for an overlap.
  double WallGap(const ConstVectorRef& q, int agent, CrowdWall wall) const;
};

/// The layout for these options (validated; deterministic). Neighbour search by a cell grid:
/// O(N).
CrowdLayout MakeCrowdLayout(const CrowdOptions& options);

/// The crowd scene of a layout (name CrowdSceneName(options)); MakeCrowdScene(options) is
/// MakeCrowdScene(MakeCrowdLayout(options)). Parameters: speed, smoothing, exit_x, exit_y.
Scene MakeCrowdScene(const CrowdLayout& layout);
/// The crowd scene for these options (MakeCrowdScene(MakeCrowdLayout(options))).
Scene MakeCrowdScene(const CrowdOptions& options);

/// The same crowd restarted from the state q (2N positions, e.g. a simulation's state at the
/// end of a segment): initial_state = q and the neighbour and wall lists rebuilt from q by the
/// rules of MakeCrowdLayout; room, exit and options unchanged. A simulation that restarts from
/// its own state with such a layout every segment ("a neighbour list rebuilt when agents
/// move") reaches horizons over which a fixed list would not suffice; each segment is an
/// ordinary scene (set its initial_time and final_time). Throws std::invalid_argument if q
/// does not have 2N finite entries.
CrowdLayout RelistCrowdLayout(const CrowdLayout& layout, const ConstVectorRef& q);

/// All pairs (i, j), i < j, of the agents of q = (x_1, y_1, ..., x_N, y_N) whose centres are
/// closer than `distance` (> 0), sorted. A cell grid of cells of size >= distance: O(N + pairs)
/// when the agents are spread no denser than discs allow.
std::vector<std::pair<int, int>> FindCrowdPairs(const ConstVectorRef& q, double distance);

/// Certificate of one state of a crowd scene against *every* pair and every wall, not only the
/// constraints the scene declares (CertifyCrowdState).
struct CrowdCertificate {
  /// Smallest gap |q_i - q_j| - 2r over all pairs (negative: overlap) and its pair; +infinity
  /// if no two centres are within 4r (pairs farther apart have gaps above 2r).
  double min_pair_gap = 0.0;
  int pair_i = -1;  ///< the pair (agents i < j) where min_pair_gap is attained: i
  int pair_j = -1;  ///< ... and j
  /// The same over the pairs *not* in the neighbour list: while it stays positive the fixed
  /// list has missed no contact.
  double min_unlisted_pair_gap = 0.0;
  int unlisted_i = -1;  ///< the unlisted pair where min_unlisted_pair_gap is attained: i
  int unlisted_j = -1;  ///< ... and j
  /// Smallest gap between an agent and a wall over all agents and all five walls, and where.
  double min_wall_gap = 0.0;
  /// The agent where min_wall_gap is attained.
  int wall_agent = -1;
  /// The wall where min_wall_gap is attained.
  CrowdWall wall = CrowdWall::kLeft;
  /// The same over the (agent, wall) combinations without a declared constraint.
  double min_unlisted_wall_gap = 0.0;

  /// No overlap beyond `tolerance` (>= 0) anywhere.
  bool Feasible(double tolerance) const;
  /// The fixed lists sufficed: no undeclared pair or wall constraint is active or violated
  /// (their gaps stay positive).
  bool ListsSufficed() const { return min_unlisted_pair_gap > 0.0 && min_unlisted_wall_gap > 0.0; }
  /// One line: the gaps and where they occur (1-based agents, as in the state names).
  std::string Summary() const;
};

/// Checks a state q of the scene of `layout` against all pairs (cell grid, O(N)) and all walls.
/// Throws std::invalid_argument if q does not have 2N entries or is not finite.
CrowdCertificate CertifyCrowdState(const CrowdLayout& layout, const ConstVectorRef& q);

/// Options from the text after "crowd:" in a scene name, comma-separated key=value pairs
/// ("N=1000,seed=3"; keys N, radius, speed, spacing, jitter, seed, cutoff, door,
/// exit_distance, smoothing, tf; the empty text gives the defaults). Throws
/// std::invalid_argument for unknown or repeated keys, malformed values and invalid options.
CrowdOptions ParseCrowdOptions(const std::string& text);
/// "crowd" for the default options, else "crowd_N1000_seed3" etc. (the options that differ
/// from the defaults, in the order of ParseCrowdOptions' keys).
std::string CrowdSceneName(const CrowdOptions& options);

/// Writes the scene of `options` as a scene file (docs/scene-files.md) that LoadScene turns
/// into the same scene as MakeCrowdScene: same states, parameters, constraint names and
/// functions (same operations in the same order, so the same values to the last bit).
void WriteCrowdSceneFile(const CrowdOptions& options, std::ostream& out);

}  // namespace moreau
