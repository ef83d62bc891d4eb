#include "moreau/model/lowered_system.hpp"

#include <algorithm>
#include <limits>

#include "../core/thread_pool.hpp"
#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau {

std::string ToString(SwitchingForm form) {
  return form == SwitchingForm::kStewart ? "stewart" : "heaviside";
}

SwitchingForm ParseSwitchingForm(const std::string& name) {
  if (name == "stewart") return SwitchingForm::kStewart;
  if (name == "heaviside") return SwitchingForm::kHeaviside;
  ThrowInvalidArgument("unknown switching form '", name, "'; expected stewart or heaviside");
}

std::string ToString(DerivativeStorage storage) {
  switch (storage) {
    case DerivativeStorage::kAutomatic:
      return "auto";
    case DerivativeStorage::kDense:
      return "dense";
    case DerivativeStorage::kSparse:
      return "sparse";
  }
  return "?";
}

std::string ToString(ConstraintFilter filter) {
  switch (filter) {
    case ConstraintFilter::kAutomatic:
      return "auto";
    case ConstraintFilter::kOff:
      return "off";
    case ConstraintFilter::kOn:
      return "on";
  }
  return "?";
}

ConstraintFilter ParseConstraintFilter(const std::string& name) {
  if (name == "auto") return ConstraintFilter::kAutomatic;
  if (name == "off") return ConstraintFilter::kOff;
  if (name == "on") return ConstraintFilter::kOn;
  ThrowInvalidArgument("unknown constraint filter '", name, "'; expected auto, off or on");
}

namespace internal {
// Defined next to each lowering (lib/model/lower_*.cpp); returns nullptr for effects that
// are not lowered to complementarity form (path constraints are handled by the DAI stepper).
std::unique_ptr<LoweredBlock> LowerEffect(const Scene& scene, const Effect& effect,
                                          const LoweringOptions& options);
}  // namespace internal

LoweredSystem::LoweredSystem(const Scene& scene, const LoweringOptions& options)
    : scene_(scene), options_(options) {
  ValidateScene(scene_, options_.require_feasible_initial_state);
  Build();
}

LoweredSystem::~LoweredSystem() = default;

LoweredSystem::LoweredSystem(const LoweredSystem& other)
    : scene_(other.scene_), options_(other.options_) {
  Build();
  inputs_ = other.inputs_;
  parameters_ = other.parameters_;
}

LoweredSystem& LoweredSystem::operator=(const LoweredSystem& other) {
  if (this != &other) {
    scene_ = other.scene_;
    options_ = other.options_;
    velocity_solver_.reset();  // its solutions belong to the old system
    Build();
    inputs_ = other.inputs_;
    parameters_ = other.parameters_;
  }
  return *this;
}

void LoweredSystem::SetThreads(int threads) {
  const int resolved = sparse_ ? internal::ThreadPool::Resolve(threads) : 1;
  if (resolved == this->threads()) return;
  pool_ = resolved > 1 ? std::make_unique<internal::ThreadPool>(resolved) : nullptr;
}

int LoweredSystem::threads() const { return pool_ ? pool_->threads() : 1; }

double LoweredSystem::worker_cpu_seconds() const {
  return pool_ ? pool_->worker_cpu_seconds() : 0.0;
}

void LoweredSystem::Build() {
  dynamics_jacobian_holder_ = std::make_unique<internal::ArgumentMatrix>();
  blocks_.clear();
  relay_names_.clear();
  std::vector<HysteresisRelay> relays;
  for (const Effect& effect : scene_.effects) {
    if (const auto* relay = std::get_if<HysteresisRelay>(&effect)) {
      relays.push_back(*relay);
      relay_names_.push_back(relay->name);
      continue;
    }
    std::unique_ptr<internal::LoweredBlock> block = internal::LowerEffect(scene_, effect, options_);
    if (block) blocks_.push_back(std::move(block));
  }
  // All relays share one time-freezing block; its memories follow the scene states.
  state_names_ = scene_.state_names;
  time_freezing_ = !relays.empty() && options_.relay_form == RelayForm::kTimeFreezing;
  memory_block_ = -1;
  if (!relays.empty()) {
    auto block = time_freezing_ ? internal::LowerHysteresis(scene_, relays)
                                : internal::LowerDiscreteRelays(scene_, relays);
    if (!time_freezing_) memory_block_ = static_cast<int>(blocks_.size());
    for (const std::string& name : block->InternalStateNames()) state_names_.push_back(name);
    blocks_.push_back(std::move(block));
  }
  state_names_.push_back("clock");
  num_states_ = static_cast<int>(state_names_.size());
  // Declared pairs: every pair of every block, before any filtering.
  num_declared_pairs_ = 0;
  int declared_algebraic = 0;
  declared_pair_offset_.clear();
  for (const auto& block : blocks_) {
    declared_pair_offset_.push_back(num_declared_pairs_);
    num_declared_pairs_ += block->num_declared_pairs();
    declared_algebraic += block->num_algebraic();  // every working set is full here
  }
  inputs_ = scene_.InputValues(scene_.initial_time);
  parameters_ = scene_.ParameterValues();
  sparse_dynamics_ = scene_.dynamics.has_sparse_state_jacobian();
  if (sparse_dynamics_) {
    RequireArgument(blocks_.empty(), scene_.name,
                    ": dynamics with a hand-written sparse Jacobian cannot be combined with "
                    "effects (their lowering needs automatic differentiation)");
    RequireArgument(
        options_.storage != DerivativeStorage::kDense, scene_.name,
        ": dynamics with a hand-written sparse Jacobian need sparse derivative storage");
  }
  // The storage follows the declared sizes, so that it does not change with the working set.
  switch (options_.storage) {
    case DerivativeStorage::kAutomatic:
      sparse_ = sparse_dynamics_ || num_states_ + declared_algebraic > kSparseStorageThreshold;
      break;
    case DerivativeStorage::kDense:
      sparse_ = false;
      break;
    case DerivativeStorage::kSparse:
      sparse_ = true;
      break;
  }
  Layout();
}

void LoweredSystem::Layout() {
  clock_rate_block_ = -1;
  num_algebraic_ = num_equations_ = num_pairs_ = 0;
  algebraic_names_.clear();
  pairs_.clear();
  continuous_algebraic_.clear();
  differentiated_.clear();
  working_pairs_.clear();
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    internal::LoweredBlock& block = *blocks_[b];
    block.layout = {scene_.num_states(), num_algebraic_, num_equations_, num_pairs_};
    num_algebraic_ += block.num_algebraic();
    num_equations_ += block.num_equations();
    num_pairs_ += block.num_pairs();
    for (const std::string& name : block.AlgebraicNames()) algebraic_names_.push_back(name);
    for (bool c : block.ContinuousAlgebraic()) continuous_algebraic_.push_back(c);
    for (bool d : block.DifferentiatedEquations()) differentiated_.push_back(d);
    for (PairInfo info : block.Pairs()) {
      info.block = static_cast<int>(b);
      pairs_.push_back(info);
    }
    for (int local : block.WorkingPairs())
      working_pairs_.push_back(declared_pair_offset_[b] + local);
    if (block.HasClockRate()) clock_rate_block_ = static_cast<int>(b);
  }
  MOREAU_ASSERT(num_algebraic_ == num_equations_ + num_pairs_,
                "lowered stage system is not square");
  MOREAU_ASSERT(static_cast<int>(working_pairs_.size()) == num_pairs_, "working pairs mismatch");
  nonzeros_valid_ = false;  // counted again when asked for (nonzeros())
}

const LoweredSystem::Nonzeros& LoweredSystem::nonzeros() const {
  if (nonzeros_valid_) return nonzeros_;
  // Structural nonzeros from one evaluation at the initial point (sparse storage; the
  // pattern does not depend on the point), every entry with dense storage.
  const double ny = num_states_, nz = num_algebraic_, ng = num_equations_, np = num_pairs_;
  nonzeros_ = {ny * ny, ny * nz, ng * ny, ng * nz, np * ny, np * nz, np * ny, np * nz};
  if (sparse_) {
    PointEvaluation e;
    const Vector y = InitialState();
    EvaluatePoint(y, InitialAlgebraicGuess(y), Derivatives::kStates, nullptr, &e);
    nonzeros_ = {e.F_y.NonZeros(), e.F_z.NonZeros(), e.G_y.NonZeros(), e.G_z.NonZeros(),
                 e.A_y.NonZeros(), e.A_z.NonZeros(), e.B_y.NonZeros(), e.B_z.NonZeros()};
  }
  nonzeros_valid_ = true;
  return nonzeros_;
}

// --- near-active constraint filter ------------------------------------------------------

bool LoweredSystem::PairFilterable(int declared) const {
  const int b = DeclaredBlock(declared);
  return blocks_[static_cast<std::size_t>(b)]->Filterable();
}

int LoweredSystem::DeclaredBlock(int declared) const {
  MOREAU_ASSERT(declared >= 0 && declared < num_declared_pairs_, "declared pair out of range");
  const auto it =
      std::upper_bound(declared_pair_offset_.begin(), declared_pair_offset_.end(), declared);
  return static_cast<int>(it - declared_pair_offset_.begin()) - 1;
}

bool LoweredSystem::has_filterable_pairs() const {
  for (const auto& block : blocks_) {
    if (block->Filterable() && block->num_declared_pairs() > 0) return true;
  }
  return false;
}

LoweredSystem::WorkingLayout LoweredSystem::working_layout() const {
  WorkingLayout layout;
  for (const auto& block : blocks_) {
    layout.z_offset.push_back(block->layout.z_offset);
    layout.pair_offset.push_back(block->layout.pair_offset);
    layout.working.push_back(block->WorkingPairs());
  }
  layout.num_algebraic = num_algebraic_;
  layout.num_pairs = num_pairs_;
  return layout;
}

bool LoweredSystem::SetWorkingPairs(const std::vector<bool>& keep) {
  RequireArgument(static_cast<int>(keep.size()) == num_declared_pairs_,
                  "SetWorkingPairs: expected ", num_declared_pairs_, " flags, got ", keep.size());
  bool changed = false;
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    internal::LoweredBlock& block = *blocks_[b];
    const int first = declared_pair_offset_[b];
    std::vector<int> working;
    for (int local = 0; local < block.num_declared_pairs(); ++local) {
      if (keep[static_cast<std::size_t>(first + local)]) working.push_back(local);
    }
    if (!block.Filterable()) {
      RequireArgument(static_cast<int>(working.size()) == block.num_declared_pairs(),
                      "SetWorkingPairs: only moving-set constraints can be left out");
      continue;
    }
    if (working != block.WorkingPairs()) {
      block.SetWorkingPairs(working);
      changed = true;
    }
  }
  if (changed) Layout();
  return changed;
}

void LoweredSystem::FilterableConstraints(const Vector& y, const Vector& velocity, Vector* values,
                                          Vector* rate_bounds) const {
  values->setConstant(num_declared_pairs_, std::numeric_limits<double>::quiet_NaN());
  rate_bounds->setConstant(num_declared_pairs_, std::numeric_limits<double>::quiet_NaN());
  internal::BlockContext context = MakeBlockContext();
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    internal::LoweredBlock& block = *blocks_[b];
    if (!block.Filterable()) continue;
    const int first = declared_pair_offset_[b];
    const int count = block.num_declared_pairs();
    block.DeclaredConstraints(context, y, velocity, values->segment(first, count),
                              rate_bounds->segment(first, count));
  }
}

double LoweredSystem::MinExcludedConstraint(const Vector& y) const {
  double smallest = std::numeric_limits<double>::infinity();
  internal::BlockContext context = MakeBlockContext();
  for (const auto& block : blocks_) {
    if (block->Filterable()) smallest = std::min(smallest, block->MinExcluded(context, y));
  }
  return smallest;
}

void LoweredSystem::ExcludedViolations(const Vector& y, double threshold,
                                       std::vector<bool>* include) const {
  internal::BlockContext context = MakeBlockContext();
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    if (!blocks_[b]->Filterable()) continue;
    blocks_[b]->ExcludedBelow(context, y, threshold, declared_pair_offset_[b], include);
  }
}

namespace {
// Calls f(i, j) for every pair that is old_working[i] and new_working[j] (both increasing):
// a value of the old layout that has a place in the new one.
template <class F>
void ForCommonWorkingPairs(const std::vector<int>& old_working, const std::vector<int>& new_working,
                           F f) {
  std::size_t i = 0;
  for (std::size_t j = 0; j < new_working.size(); ++j) {
    while (i < old_working.size() && old_working[i] < new_working[j]) ++i;
    if (i < old_working.size() && old_working[i] == new_working[j]) {
      f(static_cast<int>(i), static_cast<int>(j));
    }
  }
}
}  // namespace

Vector LoweredSystem::RemapAlgebraic(const Vector& z, const WorkingLayout& from,
                                     double fill) const {
  MOREAU_ASSERT(z.size() == from.num_algebraic, "RemapAlgebraic: wrong size");
  Vector out = Vector::Constant(num_algebraic_, fill);
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    const internal::LoweredBlock& block = *blocks_[b];
    if (!block.Filterable()) {
      out.segment(block.layout.z_offset, block.num_algebraic()) =
          z.segment(from.z_offset[b], block.num_algebraic());
      continue;
    }
    // Moving sets: one multiplier per working constraint, in the order of the constraints.
    ForCommonWorkingPairs(from.working[b], block.WorkingPairs(), [&](int i, int j) {
      out[block.layout.z_offset + j] = z[from.z_offset[b] + i];
    });
  }
  return out;
}

Vector LoweredSystem::RemapPairValues(const Vector& values, const WorkingLayout& from,
                                      double fill) const {
  MOREAU_ASSERT(values.size() == from.num_pairs, "RemapPairValues: wrong size");
  Vector out = Vector::Constant(num_pairs_, fill);
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    const internal::LoweredBlock& block = *blocks_[b];
    ForCommonWorkingPairs(from.working[b], block.WorkingPairs(), [&](int i, int j) {
      out[block.layout.pair_offset + j] = values[from.pair_offset[b] + i];
    });
  }
  return out;
}

std::vector<bool> LoweredSystem::RemapStatuses(const std::vector<bool>& a_zero,
                                               const WorkingLayout& from, bool fill) const {
  Vector values(static_cast<Eigen::Index>(a_zero.size()));
  for (std::size_t k = 0; k < a_zero.size(); ++k) values[static_cast<Eigen::Index>(k)] = a_zero[k];
  const Vector mapped = RemapPairValues(values, from, fill ? 1.0 : 0.0);
  std::vector<bool> out(static_cast<std::size_t>(num_pairs_));
  for (int k = 0; k < num_pairs_; ++k) out[static_cast<std::size_t>(k)] = mapped[k] != 0.0;
  return out;
}

Vector LoweredSystem::DeclaredAlgebraic(const Vector& z) const {
  MOREAU_ASSERT(z.size() == num_algebraic_, "DeclaredAlgebraic: wrong size");
  if (num_pairs_ == num_declared_pairs_) return z;
  Vector out = Vector::Zero(num_declared_algebraic());
  int offset = 0;
  for (const auto& block : blocks_) {
    if (!block->Filterable()) {
      out.segment(offset, block->num_algebraic()) =
          z.segment(block->layout.z_offset, block->num_algebraic());
      offset += block->num_algebraic();
      continue;
    }
    const std::vector<int> working = block->WorkingPairs();
    for (std::size_t j = 0; j < working.size(); ++j) {
      out[offset + working[j]] = z[block->layout.z_offset + static_cast<int>(j)];
    }
    offset += block->num_declared_pairs();
  }
  return out;
}

int LoweredSystem::num_declared_algebraic() const {
  return num_algebraic_ - num_pairs_ + num_declared_pairs_;
}

std::vector<std::string> LoweredSystem::declared_algebraic_names() const {
  std::vector<std::string> names;
  for (const auto& block : blocks_) {
    for (const std::string& name : block->DeclaredAlgebraicNames()) names.push_back(name);
  }
  return names;
}

Vector LoweredSystem::InitialState() const {
  Vector y(num_states_);
  y.head(scene_.num_states()) = scene_.initial_state;
  for (const auto& block : blocks_) block->InitialInternalStates(y);
  y[clock_index()] = scene_.initial_time;
  return y;
}

namespace {
// The slice of per-pair statuses belonging to one block.
std::vector<bool> BlockStatuses(const std::vector<bool>& a_zero,
                                const internal::LoweredBlock& block) {
  const auto first = a_zero.begin() + block.layout.pair_offset;
  return std::vector<bool>(first, first + block.num_pairs());
}
}  // namespace

std::vector<int> LoweredSystem::MemoryTargets(const std::vector<bool>& a_zero) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  if (clock_rate_block_ < 0) return {};
  const auto& block = *blocks_[static_cast<std::size_t>(clock_rate_block_)];
  return block.MemoryTargets(BlockStatuses(a_zero, block));
}

Vector LoweredSystem::MemorySwitchingFunctions(const Vector& y) const {
  MOREAU_ASSERT(y.size() == num_states_, "MemorySwitchingFunctions: wrong state size");
  if (memory_block_ < 0) return Vector();
  auto& block = *blocks_[static_cast<std::size_t>(memory_block_)];
  Vector out(block.num_memory_switches());
  internal::BlockContext context = MakeBlockContext();
  block.MemorySwitchingFunctions(context, y, out);
  return out;
}

void LoweredSystem::BoundMemorySwitchingFunctions(const ConstVectorRef& y_lower,
                                                  const ConstVectorRef& y_upper, Vector* lower,
                                                  Vector* upper) const {
  const double infinity = std::numeric_limits<double>::infinity();
  const int n = memory_block_ < 0
                    ? 0
                    : blocks_[static_cast<std::size_t>(memory_block_)]->num_memory_switches();
  lower->setConstant(n, -infinity);
  upper->setConstant(n, infinity);
  if (n == 0) return;
  internal::BlockContext context = MakeBlockContext();
  blocks_[static_cast<std::size_t>(memory_block_)]->MemorySwitchingBounds(context, y_lower, y_upper,
                                                                          *lower, *upper);
}

void LoweredSystem::BoundEventIndicators(const ConstVectorRef& y_lower,
                                         const ConstVectorRef& y_upper,
                                         const std::vector<bool>& a_zero, Vector* lower,
                                         Vector* upper) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  MOREAU_ASSERT(y_lower.size() == num_states_ && y_upper.size() == num_states_,
                "BoundEventIndicators: wrong state size");
  const double infinity = std::numeric_limits<double>::infinity();
  lower->setConstant(num_pairs_, -infinity);
  upper->setConstant(num_pairs_, infinity);
  internal::BlockContext context = MakeBlockContext();
  for (const auto& block : blocks_) {
    block->IndicatorBounds(context, y_lower, y_upper, a_zero, *lower, *upper);
  }
}

void LoweredSystem::SwitchMemory(int relay, Vector* y) const {
  MOREAU_ASSERT(memory_block_ >= 0 && relay >= 0 && relay < static_cast<int>(relay_names_.size()),
                "SwitchMemory: no such discrete-memory relay");
  const int index = scene_.num_states() + relay;
  (*y)[index] = (*y)[index] < 0.5 ? 1.0 : 0.0;
}

bool LoweredSystem::TimeFrozen(const std::vector<bool>& a_zero) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  if (clock_rate_block_ < 0) return false;
  const auto& block = *blocks_[static_cast<std::size_t>(clock_rate_block_)];
  return block.AnyMemoryTarget(a_zero, static_cast<std::size_t>(block.layout.pair_offset));
}

std::vector<Event> LoweredSystem::InitialEvents(double t, const Vector& y,
                                                const std::vector<bool>& a_zero) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  std::vector<Event> events;
  for (const auto& block : blocks_) {
    for (Event& event : block->InitialEvents(t, y, BlockStatuses(a_zero, *block))) {
      events.push_back(std::move(event));
    }
  }
  return events;
}

Vector LoweredSystem::InitialAlgebraicGuess(const Vector& y, const Vector* previous) const {
  Vector z;
  InitialAlgebraicGuess(y, previous, &z);
  return z;
}

void LoweredSystem::InitialAlgebraicGuess(const Vector& y, const Vector* previous,
                                          Vector* z) const {
  MOREAU_ASSERT(previous == nullptr || previous->size() == num_algebraic_,
                "InitialAlgebraicGuess: previous has the wrong size");
  MOREAU_ASSERT(previous != z, "InitialAlgebraicGuess: previous is the output");
  z->setZero(num_algebraic_);
  internal::BlockContext context = MakeBlockContext();
  for (const auto& block : blocks_) block->InitialGuess(context, y, previous, *z);
}

std::string LoweredSystem::DescribeNonFinite(const Vector& y) const {
  const int nx = scene_.num_states();
  return NonFiniteModelValue(scene_, y.head(nx), inputs_, y[clock_index()], parameters_);
}

void LoweredSystem::SetInputs(const Vector& u) {
  RequireArgument(u.size() == scene_.num_inputs(), scene_.name, ": expected ", scene_.num_inputs(),
                  " input values, got ", u.size());
  inputs_ = u;
}

void LoweredSystem::SetParameters(const Vector& p) {
  RequireArgument(p.size() == scene_.num_parameters(), scene_.name, ": expected ",
                  scene_.num_parameters(), " parameter values, got ", p.size());
  parameters_ = p;
}

void LoweredSystem::UpdateValues(const Scene& scene) {
  RequireArgument(scene.num_states() == scene_.num_states() &&
                      scene.num_parameters() == scene_.num_parameters() &&
                      scene.num_inputs() == scene_.num_inputs() &&
                      scene.effects.size() == scene_.effects.size() &&
                      scene.time_scale_input == scene_.time_scale_input,
                  "scene '", scene.name, "' does not have the structure of the lowered scene '",
                  scene_.name, "' (states, parameters, inputs, effects)");
  scene_.initial_state = scene.initial_state;
  scene_.initial_time = scene.initial_time;
  scene_.final_time = scene.final_time;
  for (std::size_t i = 0; i < scene.parameters.size(); ++i) {
    scene_.parameters[i].value = scene.parameters[i].value;
  }
  for (std::size_t i = 0; i < scene.inputs.size(); ++i) {
    scene_.inputs[i].signal = scene.inputs[i].signal;
    scene_.inputs[i].initial_guess = scene.inputs[i].initial_guess;
  }
  inputs_ = scene_.InputValues(scene_.initial_time);
  parameters_ = scene_.ParameterValues();
}

std::vector<Event> LoweredSystem::StatusEvents(double t, const std::vector<bool>& before,
                                               const std::vector<bool>& after) const {
  MOREAU_ASSERT(before.size() == pairs_.size() && after.size() == pairs_.size(),
                "StatusEvents: wrong number of pair statuses");
  // Every block's events are changes of its own statuses: none without a change (and no
  // per-block copies of the statuses, which a step loop calling this every step would
  // allocate).
  if (before == after) return {};
  std::vector<Event> events;
  for (const auto& block : blocks_) {
    for (Event& event :
         block->StatusEvents(t, BlockStatuses(before, *block), BlockStatuses(after, *block))) {
      events.push_back(std::move(event));
    }
  }
  return events;
}

void LoweredSystem::EvaluatePoint(const ConstVectorRef& y, const ConstVectorRef& z,
                                  Derivatives derivatives,
                                  const std::vector<PairRole>* velocity_roles, PointEvaluation* out,
                                  bool field_only, int switching_mode) const {
  MOREAU_ASSERT(y.size() == num_states_ && z.size() == num_algebraic_,
                "LoweredSystem::Evaluate: wrong point size");
  const int nx = scene_.num_states();
  const int ny = num_states_;
  const int nz = num_algebraic_;
  const int nu = scene_.num_inputs();
  const int np = scene_.num_parameters();
  const int clock = clock_index();

  out->F.setZero(ny);
  const bool with_states = derivatives != Derivatives::kNone;
  const bool with_all = derivatives == Derivatives::kAll;
  if (field_only) {
    // EvaluateField: G, A, B and their derivatives are sized but not read (blocks may still
    // write them), so they are not zeroed: at FESD's smooth elements this zeroing cost more
    // than the field. Storage of a new size is zeroed (nothing holds indeterminate values).
    if (out->G.size() != num_equations_) out->G.setZero(num_equations_);
    if (out->A.size() != num_pairs_) out->A.setZero(num_pairs_);
    if (out->B.size() != num_pairs_) out->B.setZero(num_pairs_);
  } else {
    out->G.setZero(num_equations_);
    out->A.setZero(num_pairs_);
    out->B.setZero(num_pairs_);
  }
  auto unread = [this, field_only](DerivativeMatrix* m, int rows, int cols) {
    if (field_only) {
      m->SetShape(rows, cols, sparse_);
    } else {
      m->SetZero(rows, cols, sparse_);
    }
  };
  if (with_states) {
    out->F_y.SetZero(ny, ny, sparse_);
    out->F_z.SetZero(ny, nz, sparse_);
    unread(&out->G_y, num_equations_, ny);
    unread(&out->G_z, num_equations_, nz);
    unread(&out->A_y, num_pairs_, ny);
    unread(&out->A_z, num_pairs_, nz);
    unread(&out->B_y, num_pairs_, ny);
    unread(&out->B_z, num_pairs_, nz);
  }
  if (with_all) {
    out->F_u.SetZero(ny, nu, sparse_);
    unread(&out->G_u, num_equations_, nu);
    unread(&out->A_u, num_pairs_, nu);
    unread(&out->B_u, num_pairs_, nu);
    out->F_p.SetZero(ny, np, sparse_);
    unread(&out->G_p, num_equations_, np);
    unread(&out->A_p, num_pairs_, np);
    unread(&out->B_p, num_pairs_, np);
  }

  internal::BlockContext context = MakeBlockContext();
  context.field_only = field_only;
  context.switching_mode = field_only ? switching_mode : -1;
  // Smooth dynamics: x' = f(x, u, clock, p); clock' = 1.
  out->F[clock] = 1.0;
  if (!scene_.dynamics.empty()) {
    internal::ArgumentMatrix& jacobian = *dynamics_jacobian_holder_;
    jacobian.Jacobian(context, scene_.dynamics, y, derivatives, &f_scratch_);
    out->F.head(nx) = f_scratch_;
    if (with_states) jacobian.AddRows(0, nx, 1.0, 0, &out->F_y, &out->F_u, &out->F_p);
  }

  if (velocity_roles != nullptr) {
    context.velocity_roles = velocity_roles;
    context.velocity = &z;
  }
  const int speed = scene_.time_scale_input;
  if (clock_rate_block_ < 0 && speed < 0) {
    for (const auto& block : blocks_) block->Evaluate(context, y, z, derivatives, out);
    FinalizeEvaluation(derivatives, out);
    return;
  }
  // Physical-time dynamics: f, the clock and the switching modes (and discrete relay fields).
  for (const auto& block : blocks_) {
    if (block->ScaledByClockRate()) block->Evaluate(context, y, z, derivatives, out);
  }
  if (clock_rate_block_ >= 0) {
    // Time-freezing: they run at the clock rate P(z): F = P F_phys, F_z = P F_phys_z +
    // F_phys dP/dz; then the relays add their own fields and memory rates.
    const auto& relays = *blocks_[static_cast<std::size_t>(clock_rate_block_)];
    const double rate = relays.ClockRate(z, with_states ? &rate_gradient_ : nullptr);
    if (with_states) {
      out->F_z.Scale(rate);
      out->F_z.AddOuter(0, 0, out->F, rate_gradient_.transpose());
      out->F_y.Scale(rate);
    }
    if (with_all) {
      out->F_u.Scale(rate);
      out->F_p.Scale(rate);
    }
    out->F *= rate;
    blocks_[static_cast<std::size_t>(clock_rate_block_)]->Evaluate(context, y, z, derivatives, out);
  }
  if (speed >= 0) {
    // Speed of time s = u[speed]: every rate so far is per unit of physical time; in numerical
    // time it is multiplied by s (dF/ds = F before the scaling).
    const double s = inputs_[speed];
    if (with_states) {
      out->F_z.Scale(s);
      out->F_y.Scale(s);
    }
    if (with_all) {
      out->F_u.Scale(s);
      out->F_u.AddBlock(0, speed, out->F);
      out->F_p.Scale(s);
    }
    out->F *= s;
  }
  // Multipliers (moving sets) are not scaled.
  for (const auto& block : blocks_) {
    if (!block->ScaledByClockRate() && !block->HasClockRate()) {
      block->Evaluate(context, y, z, derivatives, out);
    }
  }
  FinalizeEvaluation(derivatives, out);
}

void LoweredSystem::FinalizeEvaluation(Derivatives derivatives, PointEvaluation* out) const {
  if (!sparse_ || derivatives == Derivatives::kNone) return;
  for (DerivativeMatrix* m :
       {&out->F_y, &out->F_z, &out->G_y, &out->G_z, &out->A_y, &out->A_z, &out->B_y, &out->B_z}) {
    m->Finalize();
  }
  if (derivatives != Derivatives::kAll) return;
  for (DerivativeMatrix* m :
       {&out->F_u, &out->G_u, &out->A_u, &out->B_u, &out->F_p, &out->G_p, &out->A_p, &out->B_p}) {
    m->Finalize();
  }
}

}  // namespace moreau
