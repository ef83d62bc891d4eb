#include "integrator_flags.hpp"

#include <algorithm>

namespace moreau::tool {

IntegratorFlags::IntegratorFlags(CLI::App* command) {
  // Option name -> the integrators that declare it, and its first declaration (for the help).
  std::vector<std::string> order;
  std::map<std::string, std::vector<std::string>> users;
  std::map<std::string, OptionSpec> first;
  for (const IntegratorSpec& integrator : Integrators()) {
    for (const OptionSpec& option : integrator.options) {
      if (users.count(option.name) == 0) {
        order.push_back(option.name);
        first[option.name] = option;
      }
      users[option.name].push_back(integrator.name);
    }
  }
  for (const std::string& name : order) {
    const OptionSpec& spec = first.at(name);
    auto flag = std::make_unique<Flag>();
    flag->name = name;
    flag->is_bool = spec.type == OptionSpec::Type::kBool;
    std::string dashed = name;
    std::replace(dashed.begin(), dashed.end(), '_', '-');
    std::string help = spec.meaning;
    if (spec.type == OptionSpec::Type::kChoice) {
      help += " (";
      for (std::size_t i = 0; i < spec.choices.size(); ++i) {
        help += (i ? ", " : "") + spec.choices[i];
      }
      help += ")";
    }
    help += " [";
    const std::vector<std::string>& by = users.at(name);
    for (std::size_t i = 0; i < by.size(); ++i) help += (i ? ", " : "") + by[i];
    help += "]";
    if (flag->is_bool) {
      // --adaptive, or --adaptive=false
      flag->option = command->add_flag("--" + dashed, flag->value, help);
    } else {
      flag->option = command->add_option("--" + dashed, flag->text, help);
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
