// Curve reading and writing: the bundled lab files, separators, Latin-1, NaN rows, bad input.
#include "demcal/smoothing/curve.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

using namespace demcal::smoothing;
namespace fs = std::filesystem;

namespace {

// The Lourenço 2005 curves (data/walls) and their envelopes (data/walls/envelopes), bundled in the repository.
std::string walls_dir() { return std::string(DEMCAL_SOURCE_DIR) + "/data/walls"; }

// Expects parse_curve to throw a CurveError whose message holds every fragment.
void expect_error(const std::string& text, const std::vector<std::string>& fragments) {
  try {
    parse_curve(text, "bad.csv");
    FAIL() << "no error for:\n" << text;
  } catch (const CurveError& e) {
    for (const auto& f : fragments) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what() << " lacks " << f;
  }
}

}  // namespace

TEST(Curve, ReadsEveryBundledFile) {
  int files = 0;
  for (const std::string& folder : {walls_dir(), walls_dir() + "/envelopes"}) {
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (entry.path().extension() != ".csv") continue;
      const Curve c = read_curve(entry.path().string());
      ASSERT_EQ(c.column_names(), (std::vector<std::string>{"top_displacement", "horizontal_force", "drift"}))
          << entry.path();
      EXPECT_EQ(c.column("top_displacement").unit, "mm");
      EXPECT_EQ(c.column("horizontal_force").unit, "kN");
      EXPECT_EQ(c.column("drift").unit, "%");
      ASSERT_EQ(c.preamble.size(), 2u);
      EXPECT_EQ(c.preamble[0].rfind("Test unit,SW.", 0), 0u);
      // The reference line is Latin-1 or UTF-8 in the files; either way it reads as UTF-8 "Lourenço".
      EXPECT_NE(c.preamble[1].find("Louren\xC3\xA7o"), std::string::npos) << c.preamble[1];
      // Data rows = lines - 4 header lines; drift = displacement / 1000 mm in percent.
      std::ifstream in(entry.path());
      std::size_t lines = 0;
      for (std::string l; std::getline(in, l);) lines += !l.empty();
      EXPECT_EQ(c.rows(), lines - 4);
      EXPECT_DOUBLE_EQ(c.column("top_displacement").values.front(), 0.0);
      for (std::size_t i = 0; i < c.rows(); ++i)
        EXPECT_NEAR(c.column("drift").values[i], c.column("top_displacement").values[i] / 10.0, 1e-3);
      ++files;
    }
  }
  EXPECT_EQ(files, 14);
}

TEST(Curve, KeepsRepeatedAndDecreasingAbscissae) {
  const Curve c = read_curve(walls_dir() + "/FD_SW2501_Lourenco2005.csv");
  const auto& x = c.column("top_displacement").values;
  // Rows 2 and 3 of the data repeat 0.08 mm with different forces.
  EXPECT_EQ(x[1], 0.08);
  EXPECT_EQ(x[2], 0.08);
  EXPECT_EQ(c.column("horizontal_force").values[1], 11.6);
  EXPECT_EQ(c.column("horizontal_force").values[2], 12.4);
  // SW.30.1 steps back once.
  const Curve sw301 = read_curve(walls_dir() + "/FD_SW301_Lourenco2005.csv");
  const auto& y = sw301.column("top_displacement").values;
  int decreasing = 0;
  for (std::size_t i = 1; i < y.size(); ++i) decreasing += y[i] < y[i - 1];
  EXPECT_EQ(decreasing, 1);
}

TEST(Curve, SemicolonDecimalCommaTabUnitsInNamesNaNRows) {
  const Curve s = parse_curve("w [mm];F [kN]\r\n0,5;1,25\r\n\r\nNaN;NaN\r\n1,5;2\r\n", "s.csv");
  EXPECT_EQ(s.column_names(), (std::vector<std::string>{"w", "F"}));
  EXPECT_EQ(s.column("w").unit, "mm");
  ASSERT_EQ(s.rows(), 3u);
  EXPECT_EQ(s.column("w").values[0], 0.5);
  EXPECT_EQ(s.column("F").values[0], 1.25);
  EXPECT_TRUE(std::isnan(s.column("F").values[1]));
  EXPECT_EQ(s.column("w").values[2], 1.5);

  const Curve t = parse_curve("# rig 4\ntime\tforce\tdv\n(s)\t(N)\t(m)\n0\t1\t2\n1\t\t3\n2\t5\t6\n", "t.tsv");
  EXPECT_EQ(t.preamble, std::vector<std::string>{"# rig 4"});
  EXPECT_EQ(t.column("force").unit, "N");
  EXPECT_TRUE(std::isnan(t.column("force").values[1]));  // an empty cell
  EXPECT_EQ(t.column("dv").values[2], 6.0);

  const XYSeries xy = series(t, "dv", "force");
  EXPECT_EQ(xy.x, (std::vector<double>{2, 6}));
  EXPECT_EQ(xy.y, (std::vector<double>{1, 5}));
}

TEST(Curve, WriteThenReadIsIdentical) {
  Curve c;
  c.source = "mem";
  c.preamble = {"Test unit,X"};
  c.columns = {{"time", "s", {0, 0.1, 0.30000000000000004}},
               {"force", "N", {1e-300, std::nan(""), -2.5e9}},
               {"dv", "", {1.0 / 3.0, 2, 3}}};
  const fs::path path = fs::temp_directory_path() / "demcal_curve_roundtrip.csv";
  write_curve(c, path.string());
  const Curve back = read_curve(path.string());
  ASSERT_EQ(back.column_names(), c.column_names());
  EXPECT_EQ(back.preamble, c.preamble);
  for (std::size_t j = 0; j < 3; ++j) {
    EXPECT_EQ(back.columns[j].unit, c.columns[j].unit);
    for (std::size_t i = 0; i < 3; ++i) {
      const double a = c.columns[j].values[i], b = back.columns[j].values[i];
      if (std::isnan(a)) EXPECT_TRUE(std::isnan(b));
      else EXPECT_EQ(a, b);
    }
  }
  EXPECT_NE(format_curve(c).find("time,force,dv\n[s],[N],[]\n"), std::string::npos);
  fs::remove(path);
}

TEST(Curve, BadInputNamesFileLineAndColumn) {
  expect_error("", {"bad.csv", "empty"});
  expect_error("force,dv\n", {"bad.csv", "line 1", "no data"});
  expect_error("force,dv\n1,2\n", {"bad.csv", "line 2", "1 data row", "at least 2"});
  expect_error("force,dv\n1,2\n3,abc\n4,5\n", {"bad.csv", "line 3", "column 'dv'", "'abc'"});
  expect_error("force,dv\n1,x\n3,4\n", {"bad.csv", "line 2", "column 2", "'x'"});
  expect_error("force,dv\n1,nan\n3,NaN\n4,\n", {"bad.csv", "column 'dv'", "NaN"});
  expect_error("force,dv\n1,2\n3,4,5\n", {"bad.csv", "line 3", "3 cells", "expected 2"});
  expect_error("force,force\n1,2\n3,4\n", {"bad.csv", "line 1", "duplicate", "'force'"});
  expect_error("force\n0\n1\n2\n", {"bad.csv", "line 2", "one column only ('0')", "at least one displacement column"});
  expect_error("force dv\n0 1\n1 2\n", {"bad.csv", "line 2", "no numeric data rows", "'0 1'", "separated by ',', ';' or a tab"});  // spaces
  EXPECT_THROW(read_curve("/nonexistent/curve.csv"), CurveError);
  const Curve c = parse_curve("a,b\n1,2\n3,4\n", "ok.csv");
  try {
    c.column("force");
    FAIL();
  } catch (const CurveError& e) {
    EXPECT_NE(std::string(e.what()).find("ok.csv: no column 'force' (columns: a, b)"), std::string::npos) << e.what();
  }
}

// Regression cases found by fuzzing the reader (fuzz/csv_fuzz.cpp): every curve the reader returns
// is either written so that it reads back equal, or refused by the writer with a CurveError.
TEST(Curve, WriterRoundTripsOrRefusesWhatTheReaderAccepts) {
  const auto round_trips = [](const std::string& text) {
    const Curve c = parse_curve(text, "in.csv");
    const Curve back = parse_curve(format_curve(c), "back.csv");
    EXPECT_EQ(back.column_names(), c.column_names());
    EXPECT_EQ(back.preamble, c.preamble);
    ASSERT_EQ(back.rows(), c.rows());
    for (std::size_t j = 0; j < c.columns.size(); ++j) {
      EXPECT_EQ(back.columns[j].unit, c.columns[j].unit);
      for (std::size_t i = 0; i < c.rows(); ++i) {
        const double a = c.columns[j].values[i], b = back.columns[j].values[i];
        EXPECT_TRUE((std::isnan(a) && std::isnan(b)) || a == b) << i << " " << a << " " << b;
      }
    }
  };
  // One column (trailing separators in the file): written with a trailing comma so it reads back.
  round_trips("\n$2\n3,,\n4\n");
  round_trips("x;y\n[mm];[kN]\n0,5;1\n1,5;nan\n2,5;3\n");
  // A name holding a parenthesised unit after the unit was split off ("e)(N)(N)" reads as name
  // "e)(N)", unit N): written as it is, the name would lose "(N)" on reading. Refused.
  EXPECT_THROW(format_curve(parse_curve("pream)\te)(N)(N)\n0\t0\n1\t25\n2\tnan\n", "u.csv")), CurveError);

  // A tab-separated file whose preamble holds a comma-separated numeric line: written with commas,
  // that line would become the first data row. The writer refuses, naming the line.
  const Curve preamble_data = parse_curve("0,0,0\nd\tf\n0\t1\n2\t3\n", "p.csv");
  ASSERT_EQ(preamble_data.preamble, std::vector<std::string>{"0,0,0"});
  try {
    format_curve(preamble_data);
    FAIL() << "a data-like preamble line was written";
  } catch (const CurveError& e) {
    EXPECT_NE(std::string(e.what()).find("preamble line 1 '0,0,0'"), std::string::npos) << e.what();
  }
  // Names the reader would split or read as numbers are refused too.
  for (const std::string name : {"e (N)", "12", "nan"}) {
    Curve c;
    c.columns = {{name, "", {1, 2}}, {"y", "", {3, 4}}};
    EXPECT_THROW(format_curve(c), CurveError) << name;
  }
  Curve bad_unit;
  bad_unit.columns = {{"x", "m,m", {1, 2}}, {"y", "", {3, 4}}};
  EXPECT_THROW(format_curve(bad_unit), CurveError);
}
