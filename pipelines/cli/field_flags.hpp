// Command-line flags from a field table (demcal/common/field_table.hpp): each field declared with
// .flag(help) becomes the option --<key> ('_' as '-') of a subcommand, bound to an options struct,
// its help showing the struct's value as the default.
#pragma once

#include "demcal/common/field_table.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace demcal::cli {

template <class Options>
class FieldFlags {
 public:
  // Adds the flags of `table` to `app`, bound to `options`, which must outlive the parse. A bool
  // field is a flag without value; a named value (an enum) takes its name as text, set by apply().
  FieldFlags(CLI::App& app, const FieldTable<Options>& table, Options& options) {
    for (const auto& field : table.fields()) {
      if (field.help.empty()) continue;
      if (!field.flag_target) throw std::logic_error(field.key + ": no command-line flag takes this field's type");
      std::string name = "--" + field.key;
      std::replace(name.begin(), name.end(), '_', '-');
      std::visit(
          [&](auto target) {
            using Target = decltype(target);
            if constexpr (std::is_same_v<Target, NamedValue>) {
              auto text = std::make_shared<std::string>(target.name);
              app.add_option(name, *text, field.help)->capture_default_str();
              named_.emplace_back(std::move(target.set), std::move(text));
            } else if constexpr (std::is_same_v<Target, bool*>) {
              app.add_flag(name, *target, field.help);
            } else {
              app.add_option(name, *target, field.help)->capture_default_str();
            }
          },
          field.flag_target(options));
    }
  }

  // Sets the named values from their flags' text (their current names when not given), in table
  // order. Throws std::invalid_argument for a name the field does not know. Call it where the
  // command starts using the options.
  void apply() const {
    for (const auto& [set, text] : named_) set(*text);
  }

 private:
  std::vector<std::pair<std::function<void(const std::string&)>, std::shared_ptr<std::string>>> named_;
};

}  // namespace demcal::cli
