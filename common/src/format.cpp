#include "demcal/common/format.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <charconv>
#include <cmath>

namespace demcal {

std::string format_number(double value, const NumberFormat& format) {
  if (!format.non_finite.empty() && !std::isfinite(value)) return std::string(format.non_finite);
  // std::to_chars with a precision is specified as printf in the "C" locale, without printf's
  // dependence on the process's locale. The longest text: -1.8e308 in fixed notation with 100
  // decimals, 411 characters.
  assert(format.significant_digits >= 0 && format.significant_digits <= 100);
  assert(format.fixed_decimals >= -1 && format.fixed_decimals <= 100);
  std::array<char, 416> buffer;
  const auto [end, error] =
      format.fixed_decimals >= 0
          ? std::to_chars(buffer.data(), buffer.data() + buffer.size(), value, std::chars_format::fixed,
                          std::min(format.fixed_decimals, 100))
          : std::to_chars(buffer.data(), buffer.data() + buffer.size(), value, std::chars_format::general,
                          std::clamp(format.significant_digits, 0, 100));
  assert(error == std::errc());
  return std::string(buffer.data(), end);
}

std::string format_number(double value, int significant_digits) {
  return format_number(value, NumberFormat{.significant_digits = significant_digits});
}

}  // namespace demcal
