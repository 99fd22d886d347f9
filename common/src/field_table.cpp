// The untemplated pieces of field tables (field_table.hpp): the words of their messages.
#include "demcal/common/field_table.hpp"

namespace demcal {

std::string describe_json(const nlohmann::json& value) {
  std::string text = value.dump();
  return text.size() > 60 ? text.substr(0, 60) + "..." : text;
}

std::string wrong_type_message(const std::string& where, const std::string& key, const char* expected,
                               const nlohmann::json& value) {
  return where + "." + key + ": expected " + expected + ", got " + describe_json(value);
}

std::string non_finite_message(const std::string& where, const std::string& key, const nlohmann::json& value) {
  return where + "." + key + ": value must be finite, got " + describe_json(value);
}

std::optional<std::string> unknown_key_message(const nlohmann::json& j, const std::set<std::string>& known,
                                               const std::string& where) {
  if (!j.is_object()) return where + ": expected a JSON object, got " + describe_json(j);
  for (const auto& [key, value] : j.items()) {
    if (known.count(key)) continue;
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    return where + ": unknown key '" + key + "' (known: " + list + ")";
  }
  return std::nullopt;
}

}  // namespace demcal
