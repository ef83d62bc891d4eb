#include "integrator_flags.hpp"

#include <algorithm>

namespace moreau::tool {

IntegratorFlags::IntegratorFlags(CLI::App* command) {
  // Option name -> (integrator, its declaration) for every integrator that declares it.
  std::vector<std::string> order;
  std::map<std::string, std::vector<std::pair<std::string, OptionSpec>>> declarations;
  for (const IntegratorSpec& integrator : Integrators()) {
    for (const OptionSpec& option : integrator.options) {
      if (declarations.count(option.name) == 0) order.push_back(option.name);
      declarations[option.name].emplace_back(integrator.name, option);
    }
  }
  for (const std::string& name : order) {
    const auto& declared = declarations.at(name);
    const OptionSpec& spec = declared.front().second;
    auto flag = std::make_unique<Flag>();
    flag->name = name;
    flag->is_bool = spec.type == OptionSpec::Type::kBool;
    std::string dashed = name;
    std::replace(dashed.begin(), dashed.end(), '_', '-');
    // One meaning when the integrators agree, else each integrator's own.
    bool same = true;
    for (const auto& [integrator, option] : declared) same = same && option.meaning == spec.meaning;
    std::string help;
    if (same) {
      help = spec.meaning + " [";
      for (std::size_t i = 0; i < declared.size(); ++i) {
        help += (i ? ", " : "") + declared[i].first;
      }
      help += "]";
    } else {
      for (std::size_t i = 0; i < declared.size(); ++i) {
        help += (i ? "; " : "") + declared[i].first + ": " + declared[i].second.meaning;
      }
    }
    if (spec.type == OptionSpec::Type::kChoice) {
      help += " (";
      for (std::size_t i = 0; i < spec.choices.size(); ++i) {
        help += (i ? ", " : "") + spec.choices[i];
      }
      help += ")";
    }
    if (flag->is_bool) {
      // --adaptive, or --adaptive=false
      flag->option = command->add_flag("--" + dashed, flag->value, help);
    } else {
      const char* type = spec.type == OptionSpec::Type::kInteger  ? "INT"
                         : spec.type == OptionSpec::Type::kReal   ? "FLOAT"
                         : spec.type == OptionSpec::Type::kChoice ? "NAME"
                                                                  : "LIST";
      flag->option = command->add_option("--" + dashed, flag->text, help)->type_name(type);
    }
    flags_.push_back(std::move(flag));
  }
}

std::map<std::string, SettingValue> IntegratorFlags::Given() const {
  std::map<std::string, SettingValue> given;
  for (const auto& flag : flags_) {
    if (flag->option->count() == 0) continue;
    given[flag->name] = flag->is_bool ? SettingValue(flag->value) : SettingValue(flag->text);
  }
  return given;
}

}  // namespace moreau::tool
