#include "demcal/limits/limits.hpp"

#include "demcal/common/format.hpp"

#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <stdexcept>

namespace demcal::limits {

namespace {

constexpr std::size_t kCount = static_cast<std::size_t>(Limit::campaigns) + 1;

std::array<std::atomic<double>, kCount> g_values;
std::once_flag g_loaded;

const LimitInfo* find_key(std::string_view key) {
  for (const auto& i : all_limits())
    if (i.key == key) return &i;
  return nullptr;
}

void apply_setting(std::string_view text, std::string_view source) {
  const auto fail = [&](const std::string& why) {
    throw std::invalid_argument(std::string(source) + " '" + std::string(text) + "': " + why);
  };
  const auto eq = text.find('=');
  if (eq == std::string_view::npos) fail("expected KEY=N");
  const std::string_view key = text.substr(0, eq);
  const std::string number(text.substr(eq + 1));
  const LimitInfo* limit = find_key(key);
  if (!limit) {
    std::string known;
    for (const auto& i : all_limits()) known += (known.empty() ? "" : ", ") + std::string(i.key);
    fail("unknown limit '" + std::string(key) + "' (known: " + known + ")");
  }
  char* end = nullptr;
  const double v = std::strtod(number.c_str(), &end);
  if (number.empty() || end != number.c_str() + number.size() || !std::isfinite(v) || v < 1)
    fail("'" + number + "' is not a number >= 1");
  g_values[static_cast<std::size_t>(limit->limit)].store(v);
}

void load_environment() {
  for (const auto& i : all_limits()) g_values[static_cast<std::size_t>(i.limit)].store(i.default_value);
  const char* env = std::getenv("DEMCAL_LIMITS");
  if (!env) return;
  std::string_view rest(env);
  while (!rest.empty()) {
    const auto comma = rest.find(',');
    const std::string_view item = rest.substr(0, comma);
    if (!item.empty()) apply_setting(item, "DEMCAL_LIMITS");
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
}

void ensure_loaded() { std::call_once(g_loaded, load_environment); }

}  // namespace

const std::vector<LimitInfo>& all_limits() {
  static const std::vector<LimitInfo> table = {
      {Limit::blocks, "blocks", "blocks", 1e5},
      {Limit::vertices_per_block, "vertices_per_block", "vertices in one block", 1000},
      {Limit::recorded_rows, "recorded_rows", "recorded rows", 1e6},
      {Limit::time_steps, "time_steps", "time steps", 1e9},
      {Limit::file_bytes, "file_bytes", "bytes", 268435456},
      {Limit::curve_rows, "curve_rows", "data rows", 1e7},
      {Limit::parameters, "parameters", "parameters", 1000},
      {Limit::population, "population", "members of the population", 1e4},
      {Limit::iterations, "iterations", "iterations", 1e6},
      {Limit::evaluations, "evaluations", "evaluations", 1e7},
      {Limit::workers, "workers", "workers", 1024},
      {Limit::network_weights, "network_weights", "network weights", 1e7},
      {Limit::epochs, "epochs", "epochs", 1e7},
      {Limit::curve_points, "curve_points", "curve points", 1e6},
      {Limit::training_rows, "training_rows", "training rows", 1e4},
      {Limit::campaigns, "campaigns", "campaigns", 1e4},
  };
  return table;
}

const LimitInfo& info(Limit limit) { return all_limits()[static_cast<std::size_t>(limit)]; }

double value(Limit limit) {
  ensure_loaded();
  return g_values[static_cast<std::size_t>(limit)].load();
}

bool exceeds(Limit limit, double count) { return !(count <= value(limit)); }

std::string number_text(double v) {
  if (std::isfinite(v) && std::fabs(v) < 1e15 && v == std::floor(v)) return format_number(v, {.fixed_decimals = 0});
  return format_number(v, 6);
}

std::string message(Limit limit, double count) {
  const LimitInfo& i = info(limit);
  const std::string key(i.key);
  return number_text(count) + " " + std::string(i.noun) + " exceed the limit of " + number_text(value(limit)) +
         " (limit '" + key + "'; raise it with --limit " + key + "=N or DEMCAL_LIMITS=" + key + "=N)";
}

std::optional<std::string> check(Limit limit, double count) {
  if (!exceeds(limit, count)) return std::nullopt;
  return message(limit, count);
}

void require_within(Limit limit, double count, std::string_view subject) {
  if (auto m = check(limit, count)) throw std::invalid_argument(std::string(subject) + ": " + *m);
}

std::optional<std::string> check_file_size(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return std::nullopt;  // a pipe or device: read as is
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return std::nullopt;
  if (auto m = check(Limit::file_bytes, static_cast<double>(size))) return "the file is too large: " + *m;
  return std::nullopt;
}

void set_from_text(std::string_view key_equals_value, bool export_to_environment) {
  ensure_loaded();
  apply_setting(key_equals_value, "--limit");
  if (!export_to_environment) return;
  std::string joined;  // every limit not at its default, so that setting one twice exports it once
  for (const auto& i : all_limits())
    if (value(i.limit) != i.default_value)
      joined += (joined.empty() ? "" : ",") + std::string(i.key) + "=" + number_text(value(i.limit));
  setenv("DEMCAL_LIMITS", joined.c_str(), 1);
}

void reset() {
  std::call_once(g_loaded, [] {});  // so that a later first use does not load over this
  load_environment();
}

}  // namespace demcal::limits
