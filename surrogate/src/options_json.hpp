// Private to the surrogate module: reading an options struct from its JSON object.
#pragma once

#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>

namespace demcal::surrogate::detail {

// Reads `json` key by key with set(options, key, value), which assigns one key and throws for an
// unknown one; errors name `where`, the key and its value (a nested object's reader names its own
// key). The result is validated (Validate()).
template <class Options, class Set>
Options options_from_json(const nlohmann::json& json, const std::string& where, Set set) {
  if (!json.is_object()) throw std::invalid_argument(where + ": must be an object");
  Options o;
  for (const auto& [key, value] : json.items()) {
    try {
      set(o, key, value);
    } catch (const std::exception& e) {
      const std::string located = where + "." + key, what = e.what();
      if (what.rfind(located, 0) == 0) throw;  // a nested object's reader has named it already
      throw std::invalid_argument(located + " = " + value.dump() + ": " + what);
    }
  }
  try {
    o.Validate();
  } catch (const std::exception& e) {
    throw std::invalid_argument(where + ": " + e.what());
  }
  return o;
}

}  // namespace demcal::surrogate::detail
