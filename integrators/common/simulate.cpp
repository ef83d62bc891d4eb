// Simulate(): the one entry point every front end uses (include/moreau/integrators/simulate.hpp).
#include "moreau/integrators/simulate.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "integrator_entry.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/model/expression.hpp"

namespace moreau {
namespace internal {
namespace {

std::string Describe(const SettingValue& value) {
  if (std::holds_alternative<std::string>(value)) {
    return "'" + std::get<std::string>(value) + "'";
  }
  return FormatSetting(value);
}

[[noreturn]] void ThrowWrongType(const OptionSpec& spec, const SettingValue& value) {
  std::string expected;
  switch (spec.type) {
    case OptionSpec::Type::kBool:
      expected = "true or false";
      break;
    case OptionSpec::Type::kInteger:
      expected = "an integer";
      break;
    case OptionSpec::Type::kReal:
      expected = "a number";
      break;
    case OptionSpec::Type::kRealList:
      expected = "a list of numbers";
      break;
    case OptionSpec::Type::kChoice: {
      for (const std::string& choice : spec.choices) {
        expected += (expected.empty() ? "one of " : ", ") + choice;
      }
      break;
    }
  }
  ThrowInvalidArgument("bad value ", Describe(value), " for option '", spec.name, "': expected ",
                       expected);
}

// Parses all of `text` as a number (strtod: also "inf" and "1e-8").
bool ParseReal(const std::string& text, double* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

}  // namespace

void ThrowUnknownOption(const IntegratorSpec& spec, const std::string& name) {
  std::string declaring;
  std::vector<std::string> all;
  for (const IntegratorSpec& other : Integrators()) {
    for (const OptionSpec& option : other.options) {
      if (std::find(all.begin(), all.end(), option.name) == all.end()) all.push_back(option.name);
      if (option.name == name) declaring += (declaring.empty() ? "" : ", ") + other.name;
    }
  }
  if (!declaring.empty()) {
    ThrowInvalidArgument("option '", name, "' does not apply to integrator '", spec.name,
                         "' (an option of ", declaring, ")");
  }
  std::vector<std::string> own;
  for (const OptionSpec& option : spec.options) own.push_back(option.name);
  // The closest of the integrator's own options, else of any integrator's.
  std::string closest = ClosestName(name, own);
  if (closest.empty()) closest = ClosestName(name, all);
  ThrowInvalidArgument("unknown option '", name, "' for integrator '", spec.name, "'",
                       closest.empty() ? std::string() : "; did you mean '" + closest + "'?");
}

bool SettingToBool(const OptionSpec& spec, const SettingValue& value) {
  if (const bool* b = std::get_if<bool>(&value)) return *b;
  if (const std::string* s = std::get_if<std::string>(&value)) {
    if (*s == "true" || *s == "1" || *s == "yes" || *s == "on") return true;
    if (*s == "false" || *s == "0" || *s == "no" || *s == "off") return false;
  }
  ThrowWrongType(spec, value);
}

long SettingToInteger(const OptionSpec& spec, const SettingValue& value) {
  if (const long* i = std::get_if<long>(&value)) return *i;
  double real = 0.0;
  bool is_number = false;
  if (const double* d = std::get_if<double>(&value)) {
    real = *d;
    is_number = true;
  } else if (const std::string* s = std::get_if<std::string>(&value)) {
    is_number = ParseReal(*s, &real);
  }
  // Whole numbers only (3.0 is accepted, 3.5 is not), within the range of long.
  if (!is_number || !std::isfinite(real) || real != std::floor(real) || std::fabs(real) > 9e18) {
    ThrowWrongType(spec, value);
  }
  return static_cast<long>(real);
}

double SettingToReal(const OptionSpec& spec, const SettingValue& value) {
  if (const double* d = std::get_if<double>(&value)) return *d;
  if (const long* i = std::get_if<long>(&value)) return static_cast<double>(*i);
  if (const std::string* s = std::get_if<std::string>(&value)) {
    double real = 0.0;
    if (ParseReal(*s, &real)) return real;
  }
  ThrowWrongType(spec, value);
}

std::string SettingToChoice(const OptionSpec& spec, const SettingValue& value) {
  if (const std::string* s = std::get_if<std::string>(&value)) {
    for (const std::string& choice : spec.choices) {
      if (*s == choice) return *s;
    }
  }
  ThrowWrongType(spec, value);
}

std::vector<double> SettingToRealList(const OptionSpec& spec, const SettingValue& value) {
  if (const auto* list = std::get_if<std::vector<double>>(&value)) return *list;
  if (const std::string* s = std::get_if<std::string>(&value)) {
    // "0.1,0.2,0.5" (the command line's form).
    std::vector<double> list;
    std::stringstream stream(*s);
    std::string item;
    while (std::getline(stream, item, ',')) {
      double real = 0.0;
      if (!ParseReal(item, &real)) ThrowWrongType(spec, value);
      list.push_back(real);
    }
    return list;
  }
  if (std::holds_alternative<double>(value) || std::holds_alternative<long>(value)) {
    return {SettingToReal(spec, value)};
  }
  ThrowWrongType(spec, value);
}

namespace {

const std::vector<IntegratorEntry>& Entries() {
  static const std::vector<IntegratorEntry> entries = {RadauEntry(), TimeSteppingEntry(),
                                                       FesdEntry(), IdaEntry(), AlphaDaiEntry()};
  return entries;
}

const IntegratorEntry& FindEntry(const std::string& name) {
  for (const IntegratorEntry& entry : Entries()) {
    if (entry.spec.name == name) return entry;
  }
  std::string valid = "auto";
  for (const IntegratorEntry& entry : Entries()) valid += ", " + entry.spec.name;
  ThrowInvalidArgument("unknown integrator '", name, "'; available: ", valid);
}

bool Supports(const IntegratorSpec& spec, const Effect& effect) {
  const std::string kind = EffectKind(effect);
  for (const std::string& supported : spec.supported_effects) {
    if (supported == kind) return true;
  }
  return false;
}

}  // namespace
}  // namespace internal

std::string FormatSetting(const SettingValue& value) {
  std::ostringstream out;
  out.precision(17);
  std::visit(
      [&out](const auto& v) {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, bool>) {
          out << (v ? "true" : "false");
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
          out << "[";
          for (std::size_t i = 0; i < v.size(); ++i) out << (i ? ", " : "") << v[i];
          out << "]";
        } else {
          out << v;
        }
      },
      value);
  return out.str();
}

std::string ToString(OptionSpec::Type type) {
  switch (type) {
    case OptionSpec::Type::kBool:
      return "bool";
    case OptionSpec::Type::kInteger:
      return "integer";
    case OptionSpec::Type::kReal:
      return "real";
    case OptionSpec::Type::kChoice:
      return "choice";
    case OptionSpec::Type::kRealList:
      return "list of reals";
  }
  return "?";
}

const OptionSpec* IntegratorSpec::FindOption(const std::string& option) const {
  for (const OptionSpec& spec : options) {
    if (spec.name == option) return &spec;
  }
  return nullptr;
}

const std::vector<IntegratorSpec>& Integrators() {
  static const std::vector<IntegratorSpec> specs = [] {
    std::vector<IntegratorSpec> list;
    for (const internal::IntegratorEntry& entry : internal::Entries()) list.push_back(entry.spec);
    return list;
  }();
  return specs;
}

const IntegratorSpec& FindIntegrator(const std::string& name) {
  return internal::FindEntry(name).spec;
}

std::vector<std::string> IntegratorsSupporting(const Scene& scene) {
  std::vector<std::string> names;
  for (const IntegratorSpec& spec : Integrators()) {
    bool all = scene.time_scale_input < 0 || spec.supports_time_scale;
    for (const Effect& effect : scene.effects) all = all && internal::Supports(spec, effect);
    if (all) names.push_back(spec.name);
  }
  return names;
}

std::string AutomaticIntegrator(const Scene& scene) {
  if (scene.effects.empty() && scene.time_scale_input < 0) return "radau";
  const std::vector<std::string> supporting = IntegratorsSupporting(scene);
  for (const char* preferred : {"fesd", "alpha", "ida", "timestepping"}) {
    for (const std::string& name : supporting) {
      if (name == preferred) return name;
    }
  }
  RequireSupportedEffects(scene, "fesd");  // throws, naming what no integrator supports
  return "fesd";
}

void RequireSupportedEffects(const Scene& scene, const std::string& name) {
  const IntegratorSpec& spec = FindIntegrator(name);
  // The integrators that would take the scene, for the message.
  auto alternatives = [&scene, &name](const std::string& what) {
    std::string list;
    for (const std::string& other : IntegratorsSupporting(scene)) {
      if (other != name) list += (list.empty() ? "" : ", ") + other;
    }
    if (list.empty()) return std::string("; no integrator supports this scene's effects together");
    return "; " + what + ": " + list;
  };
  // The messages are built only on failure (alternatives() asks every integrator).
  if (!(scene.time_scale_input < 0 || spec.supports_time_scale)) {
    ThrowInvalidArgument(spec.title, " does not support the speed of time of scene '", scene.name,
                         "' (time_scale_input)", alternatives("integrators that do"));
  }
  for (const Effect& effect : scene.effects) {
    if (!internal::Supports(spec, effect)) {
      ThrowInvalidArgument(spec.title, " does not support the ", EffectKind(effect), " '",
                           EffectName(effect), "' of scene '", scene.name, "'",
                           alternatives("integrators that support the scene"));
    }
  }
}

double SimulationResult::Stat(const std::string& name) const {
  for (const auto& [stat, value] : stats) {
    if (stat == name) return value;
  }
  ThrowInvalidArgument("integrator '", integrator, "' has no statistic '", name, "'");
}

std::map<std::string, SettingValue> WithSceneDefaults(
    const Scene& scene, const std::string& integrator,
    const std::map<std::string, SettingValue>& given) {
  std::map<std::string, SettingValue> options = given;
  const SceneDefaults& defaults = scene.defaults;
  if (defaults.empty()) return options;
  const IntegratorSpec& spec = FindIntegrator(integrator);
  // The option of this integrator that takes a default (IDA calls its largest step max_step).
  auto option = [&spec](std::initializer_list<const char*> names) -> const OptionSpec* {
    for (const char* name : names) {
      if (const OptionSpec* found = spec.FindOption(name)) return found;
    }
    return nullptr;
  };
  auto apply = [&](std::initializer_list<const char*> names, const SettingValue& value) {
    const OptionSpec* found = option(names);
    if (found != nullptr && options.count(found->name) == 0) options[found->name] = value;
  };
  // Step-control defaults only where the steps are error-controlled: a given h means fixed
  // steps (shooting codes), unless an error-control option comes with it.
  bool error_controlled = given.count("h") == 0;
  for (const char* control : {"rtol", "atol", "h0"}) error_controlled |= given.count(control) > 0;
  if (const auto it = given.find("adaptive"); it != given.end()) {
    if (const OptionSpec* adaptive = spec.FindOption("adaptive")) {
      error_controlled |= internal::SettingToBool(*adaptive, it->second);
    }
  }
  if (error_controlled) {
    if (defaults.relative_tolerance > 0.0) apply({"rtol"}, defaults.relative_tolerance);
    if (defaults.absolute_tolerance > 0.0) apply({"atol"}, defaults.absolute_tolerance);
    if (defaults.initial_step > 0.0) apply({"h0"}, defaults.initial_step);
    if (defaults.max_step > 0.0) apply({"h_max", "max_step"}, defaults.max_step);
  }
  // Output times, unless the user asked for other ones; only those inside the horizon (the
  // user may have shortened it).
  if (given.count("output_times") == 0 && given.count("output_dt") == 0) {
    std::vector<double> times;
    for (double t : defaults.output_times) {
      if (t >= scene.initial_time && t <= scene.final_time) times.push_back(t);
    }
    if (!times.empty()) apply({"output_times"}, times);
    if (defaults.output_step > 0.0) apply({"output_dt"}, defaults.output_step);
  }
  return options;
}

void ValidateSimulationSettings(const Scene& scene, const SimulationSettings& settings) {
  const std::string name =
      settings.integrator == "auto" ? AutomaticIntegrator(scene) : settings.integrator;
  const internal::IntegratorEntry& entry = internal::FindEntry(name);
  RequireSupportedEffects(scene, name);
  entry.check(WithSceneDefaults(scene, name, settings.options));
}

SimulationResult Simulate(const Scene& scene, const SimulationSettings& settings,
                          const ProgressCallback& progress) {
  const double wall_start = WallSeconds();
  const std::string name =
      settings.integrator == "auto" ? AutomaticIntegrator(scene) : settings.integrator;
  const internal::IntegratorEntry& entry = internal::FindEntry(name);
  RequireSupportedEffects(scene, name);
  SimulationResult result =
      entry.run(scene, WithSceneDefaults(scene, name, settings.options), progress);
  result.wall_seconds = WallSeconds() - wall_start;
  result.scene = scene.name;
  result.state_names = scene.state_names;
  return result;
}

struct Simulator::Impl {
  Scene base;     // the scene as given
  Scene working;  // base with this run's values
  std::string integrator;
  internal::IntegratorEntry::Prepared run;
};

Simulator::Simulator(const Scene& scene, const SimulationSettings& settings)
    : impl_(std::make_unique<Impl>()) {
  ValidateScene(scene);
  impl_->integrator =
      settings.integrator == "auto" ? AutomaticIntegrator(scene) : settings.integrator;
  const internal::IntegratorEntry& entry = internal::FindEntry(impl_->integrator);
  RequireSupportedEffects(scene, impl_->integrator);
  impl_->base = scene;
  impl_->working = scene;
  impl_->run = entry.prepare(scene, WithSceneDefaults(scene, impl_->integrator, settings.options));
}

Simulator::~Simulator() = default;

SimulationResult Simulator::Run(const std::vector<std::pair<std::string, double>>& values,
                                const ProgressCallback& progress) {
  Scene& working = impl_->working;
  const Scene& base = impl_->base;
  // Back to the scene's own values (cheap: no model function is copied), then this run's.
  working.initial_state = base.initial_state;
  working.final_time = base.final_time;
  for (std::size_t i = 0; i < base.parameters.size(); ++i) {
    working.parameters[i].value = base.parameters[i].value;
  }
  const double wall_start = WallSeconds();
  for (const auto& [name, value] : values) SetSceneValue(&working, name, value);
  SimulationResult result = impl_->run(working, progress);
  result.wall_seconds = WallSeconds() - wall_start;
  return result;
}

const std::string& Simulator::integrator() const { return impl_->integrator; }
const Scene& Simulator::scene() const { return impl_->base; }

}  // namespace moreau
