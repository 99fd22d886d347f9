#include <demcal/common/format.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <locale>
#include <sstream>
#include <string>
#include <vector>

using demcal::format_number;
using demcal::NumberFormat;
using demcal::round_trip_digits;

namespace {

const double kInf = std::numeric_limits<double>::infinity();
const double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<double> sample_values() {
  return {0.0, -0.0, 1.0, -1.0, 0.5, 2.5, 0.1, 1.0 / 3.0, 0.000139, 1234567.0, 2000000002.0, 1e15, 1e-12,
          -4.2e9, 6.02214076e23, 1.7976931348623157e308, 5e-324, 2.2250738585072014e-308, 123.456789012345678,
          kInf, -kInf, kNaN, -kNaN};
}

std::string printf_text(const char* pattern, int precision, double value) {
  char buffer[512];
  std::snprintf(buffer, sizeof buffer, pattern, precision, value);
  return buffer;
}

}  // namespace

TEST(FormatNumber, SignificantDigitsAreThoseOfPrintfAndOstream) {
  for (double v : sample_values())
    for (int digits = 0; digits <= 20; ++digits) {
      std::ostringstream stream;
      stream.precision(digits);
      stream << v;
      EXPECT_EQ(format_number(v, digits), printf_text("%.*g", digits, v)) << v << " " << digits;
      EXPECT_EQ(format_number(v, digits), stream.str()) << v << " " << digits;
    }
}

TEST(FormatNumber, FixedDecimalsAreThoseOfPrintf) {
  for (double v : sample_values())
    for (int decimals : {0, 1, 2, 3, 6, 17, 100})
      EXPECT_EQ(format_number(v, {.fixed_decimals = decimals}), printf_text("%.*f", decimals, v)) << v << " " << decimals;
}

TEST(FormatNumber, Examples) {
  EXPECT_EQ(format_number(0.000139, 3), "0.000139");
  EXPECT_EQ(format_number(1234567.0, 3), "1.23e+06");
  EXPECT_EQ(format_number(2.5, 6), "2.5");
  EXPECT_EQ(format_number(1234567.0, 6), "1.23457e+06");
  EXPECT_EQ(format_number(0.1, round_trip_digits), "0.10000000000000001");
  EXPECT_EQ(format_number(2.0, {.fixed_decimals = 3}), "2.000");
  EXPECT_EQ(format_number(3.0, {.fixed_decimals = 0}), "3");
  EXPECT_EQ(format_number(kNaN, 6), "nan");
  EXPECT_EQ(format_number(-kInf, 6), "-inf");
}

TEST(FormatNumber, NonFiniteTextReplacesOnlyNonFiniteValues) {
  const NumberFormat cell{.fixed_decimals = 1, .non_finite = "-"};
  EXPECT_EQ(format_number(kNaN, cell), "-");
  EXPECT_EQ(format_number(-kNaN, cell), "-");
  EXPECT_EQ(format_number(kInf, cell), "-");
  EXPECT_EQ(format_number(-kInf, cell), "-");
  EXPECT_EQ(format_number(12.34, cell), "12.3");
  EXPECT_EQ(format_number(kNaN, {.significant_digits = 10, .non_finite = "n/a"}), "n/a");
}

TEST(FormatNumber, RoundTripDigitsReadBackToTheSameDouble) {
  for (double v : sample_values()) {
    if (!std::isfinite(v)) continue;
    EXPECT_EQ(std::strtod(format_number(v, round_trip_digits).c_str(), nullptr), v) << v;
  }
}

// The text does not follow the process's C locale (a decimal comma there, or digit grouping).
// A decimal comma and digit grouping in the program's global C++ locale (what a stream would write)
// change nothing: the text is the "C" locale's whatever the process sets.
TEST(FormatNumber, IndependentOfTheGlobalLocale) {
  struct CommaDecimal : std::numpunct<char> {
    char do_decimal_point() const override { return ','; }
    char do_thousands_sep() const override { return '.'; }
    std::string do_grouping() const override { return "\3"; }
  };
  const std::locale before = std::locale::global(std::locale(std::locale::classic(), new CommaDecimal));
  std::ostringstream stream;
  stream << 1234.5;
  const std::string significant = format_number(1234.5, 6), fixed = format_number(0.25, {.fixed_decimals = 2});
  std::locale::global(before);
  EXPECT_EQ(stream.str(), "1.234,5");  // the locale is in force
  EXPECT_EQ(significant, "1234.5");
  EXPECT_EQ(fixed, "0.25");
}
