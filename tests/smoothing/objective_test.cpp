// Objective 1 on hand-computed cases, the loading-envelope rule, channel matching and errors.
#include "demcal/smoothing/objective.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace demcal::smoothing;

namespace {

Curve curve(const std::string& source, std::vector<Column> columns) {
  Curve c;
  c.source = source;
  c.columns = std::move(columns);
  return c;
}

ObjectiveOptions points(int n) {
  ObjectiveOptions o;
  o.points = n;
  return o;
}

template <class F>
void expect_curve_error(F f, const std::vector<std::string>& fragments) {
  try {
    f();
    FAIL() << "no error";
  } catch (const CurveError& e) {
    for (const auto& s : fragments) EXPECT_NE(std::string(e.what()).find(s), std::string::npos) << e.what() << " lacks " << s;
  }
}

}  // namespace

TEST(Objective1, EqualLengthsThreePoints) {
  const Curve e = curve("e.csv", {{"force", "N", {0, 1, 2}}, {"dv", "m", {0, 1, 2}}});
  const Curve s = curve("s.csv", {{"force", "N", {0, 2, 2}}, {"dv", "m", {0, 1, 2}}});
  const auto r = objective1(e, s, points(3));  // w = 0, 1, 2: differences 0, -1, 0
  EXPECT_DOUBLE_EQ(r.fitness, 1.0);
  EXPECT_DOUBLE_EQ(r.channels.at("dv"), 1.0);
}

TEST(Objective1, UnequalLengthsAndAWindowThatClipsBoth) {
  // Experiment F = 2w on [0, 3] (4 rows), simulation F = w on [1, 4] (3 rows): window [1, 3].
  const Curve e = curve("e.csv", {{"dv", "", {0, 1, 2, 3}}, {"force", "", {0, 2, 4, 6}}});
  const Curve s = curve("s.csv", {{"dv", "", {1, 2.5, 4}}, {"force", "", {1, 2.5, 4}}});
  // 5 points w = 1, 1.5, 2, 2.5, 3; difference = w: 1 + 2.25 + 4 + 6.25 + 9 = 22.5.
  EXPECT_DOUBLE_EQ(objective1(e, s, points(5)).fitness, std::sqrt(22.5));
  // 200 points w_k = 1 + 2k/199: sum (1 + 2k/199)^2 = 200 + 4*19900/199 + 4*(199*200*399/6)/199^2.
  const double expected = std::sqrt(200.0 + 4.0 * 19900.0 / 199.0 + 4.0 * 2646700.0 / 39601.0);
  EXPECT_NEAR(objective1(e, s).fitness, expected, 1e-12 * expected);
  // Symmetric in the two curves.
  EXPECT_NEAR(objective1(s, e).fitness, expected, 1e-12 * expected);
}

TEST(Objective1, TwoChannelsWeightedTimeIgnored) {
  const Curve e = curve("e.csv", {{"time", "s", {0, 1, 2}}, {"force", "N", {0, 1, 2}},
                                  {"dv", "m", {0, 1, 2}}, {"dh", "m", {0, 2, 4}}, {"extra", "", {5, 6, 7}}});
  const Curve s = curve("s.csv", {{"time", "s", {9, 9, 9}}, {"dh", "m", {0, 2, 4}},
                                  {"force", "N", {0, 2, 2}}, {"dv", "m", {0, 1, 2}}});
  ObjectiveOptions o = points(3);
  o.channel_weights["dh"] = 3;
  const auto r = objective1(e, s, o);
  ASSERT_EQ(r.channels.size(), 2u);  // "extra" is only in the experiment; "time" is ignored
  EXPECT_DOUBLE_EQ(r.channels.at("dv"), 1.0);
  EXPECT_DOUBLE_EQ(r.channels.at("dh"), 1.0);
  EXPECT_DOUBLE_EQ(r.fitness, 1.0 + 3.0 * 1.0);
  EXPECT_EQ(common_channels(e, s, o), (std::vector<std::string>{"dv", "dh"}));
}

TEST(Objective1, LoadingEnvelopeRule) {
  // Back and forth, a repeated displacement and a NaN row (cycle separator).
  const XYSeries path{{0, 1, 0.5, 1, 2, NAN, 1.5, 3}, {0, 1, 9, 5, 2, 7, 9, 3}};
  const XYSeries env = loading_envelope(path);
  EXPECT_EQ(env.x, (std::vector<double>{0, 1, 2, 3}));
  EXPECT_EQ(env.y, (std::vector<double>{0, 5, 2, 3}));  // the latest force at w = 1 counts
  EXPECT_DOUBLE_EQ(interpolate(env, 0.5), 2.5);
  EXPECT_DOUBLE_EQ(interpolate(env, 2.5), 2.5);
  EXPECT_DOUBLE_EQ(interpolate(env, -1), 0);
  EXPECT_DOUBLE_EQ(interpolate(env, 7), 3);
  // The fitness sees only the envelope: unloading loops change nothing.
  const XYSeries monotone{{0, 1, 2, 3}, {0, 5, 2, 3}};
  const XYSeries other{{0, 3}, {0, 0}};
  EXPECT_DOUBLE_EQ(channel_misfit(path, other, 4), channel_misfit(monotone, other, 4));
  EXPECT_DOUBLE_EQ(channel_misfit(monotone, other, 4), std::sqrt(0 + 25 + 4 + 9));
}

// A series compared with many others is enveloped once: the envelope of an envelope is itself, and
// envelope_misfit of two envelopes is channel_misfit of their series, to the bit, under either window.
TEST(Objective1, EnvelopeMisfitOfTheEnvelopesIsTheChannelMisfit) {
  const XYSeries measured{{0, 0.4, 0.3, 1.1, 1.1, NAN, 2.05, 1.9, 3.3}, {0, 1.7, 9, 4.1, 5.3, 7, 2.2, 9, 3.9}};
  const XYSeries simulated{{-0.1, 0.2, 0.9, 0.85, 2.6, 2.9}, {0.3, 1.1, 4.4, 6, NAN, 3.3}};
  const XYSeries e = loading_envelope(measured), s = loading_envelope(simulated);
  EXPECT_EQ(loading_envelope(e).x, e.x);
  EXPECT_EQ(loading_envelope(e).y, e.y);
  for (const auto window : {ObjectiveWindow::common, ObjectiveWindow::measured})
    for (const int n : {2, 7, 200})
      EXPECT_EQ(envelope_misfit(e, s, n, "dv", window), channel_misfit(measured, simulated, n, "dv", window)) << n;
  expect_curve_error([&] { envelope_misfit(XYSeries{{0}, {1}}, s, 7, "dv"); }, {"dv", "fewer than 2 loading points"});
  EXPECT_THROW(envelope_misfit(e, s, 1), std::invalid_argument);
}

TEST(Objective1, Errors) {
  const Curve e = curve("e.csv", {{"force", "", {0, 1}}, {"dv", "", {0, 1}}});
  const Curve no_force = curve("s.csv", {{"F", "", {0, 1}}, {"dv", "", {0, 1}}});
  const Curve other_channel = curve("s.csv", {{"force", "", {0, 1}}, {"dh", "", {0, 1}}});
  const Curve apart = curve("s.csv", {{"force", "", {0, 1}}, {"dv", "", {2, 3}}});
  expect_curve_error([&] { objective1(e, no_force); }, {"s.csv", "no force column 'force'", "F, dv"});
  expect_curve_error([&] { objective1(e, other_channel); }, {"no displacement column in common", "e.csv", "(dv)", "s.csv", "(dh)"});
  expect_curve_error([&] { objective1(e, apart); }, {"channel 'dv'", "do not overlap", "[0, 1]", "[2, 3]"});
  ObjectiveOptions o;
  o.channel_weights["dh"] = 2;
  expect_curve_error([&] { objective1(e, e, o); }, {"'dh'", "not a common channel"});
  o = {};
  o.channel_weights["dv"] = -1;
  EXPECT_THROW(o.Validate(), std::invalid_argument);
  EXPECT_THROW(points(1).Validate(), std::invalid_argument);
}

TEST(Objective1, MeasuredWindowScoresAGaugeThatHardlyMovesOverTheWholeMeasuredRange) {
  // A second gauge measured from 0 to 4 under a force equal to its displacement; in the run it
  // follows to 0.01 and comes back while the force rises the same way (the load point's channel
  // matches exactly).
  const std::vector<double> w = {0, 0.01, 1, 2, 3, 4};
  const Curve e = curve("e.csv", {{"force", "", w}, {"dv", "", w}, {"dh", "", w}});
  const Curve s = curve("s.csv", {{"force", "", w}, {"dv", "", w}, {"dh", "", {0, 0.01, 0, 0, 0, 0}}});
  // The paper's window is [0, 0.01] on dh, where the two agree: a perfect score.
  EXPECT_DOUBLE_EQ(objective1(e, s, points(5)).fitness, 0.0);
  // The measured window is [0, 4]; the run is held at its last envelope point (0.01, 0.01) beyond:
  // w = 0, 1, 2, 3, 4 against 0, 0.01, 0.01, 0.01, 0.01.
  ObjectiveOptions measured = points(5);
  measured.window = ObjectiveWindow::measured;
  const auto r = objective1(e, s, measured);
  EXPECT_DOUBLE_EQ(r.channels.at("dv"), 0.0);
  EXPECT_NEAR(r.channels.at("dh"), std::sqrt(0.99 * 0.99 + 1.99 * 1.99 + 2.99 * 2.99 + 3.99 * 3.99), 1e-12);
  // A run that reaches further is scored over the measured range alone, as with the paper's window.
  const Curve longer = curve("s.csv", {{"force", "", {0, 1, 2, 3, 4, 9}}, {"dv", "", {0, 1, 2, 3, 4, 5}}, {"dh", "", {0, 1, 2, 3, 4, 5}}});
  EXPECT_DOUBLE_EQ(objective1(e, longer, measured).fitness, 0.0);
  EXPECT_DOUBLE_EQ(objective1(e, longer, points(5)).fitness, 0.0);
  EXPECT_EQ(parse_objective_window("measured"), ObjectiveWindow::measured);
  EXPECT_EQ(to_string(parse_objective_window("common")), "common");
  try {
    parse_objective_window("shared");
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'shared'"), std::string::npos) << e.what();
  }
}

TEST(Objective1, EitherWindowScoresAGaugeThatOnlyMovedBackwards) {
  // The run's second gauge goes against the loading direction from its first reading (an abutment
  // pushed back): its envelope is that reading alone, (0, 0.5). It shares no range with the
  // measurement, so both windows hold it over the measured [0, 4].
  const std::vector<double> w = {0, 1, 2, 3, 4};
  const Curve e = curve("e.csv", {{"force", "", w}, {"dh", "", w}});
  const Curve s = curve("s.csv", {{"force", "", {0.5, 1, 2, 3, 4}}, {"dh", "", {0, -0.1, -0.2, -0.1, -0.3}}});
  ObjectiveOptions measured = points(5);
  measured.window = ObjectiveWindow::measured;
  const double held = std::sqrt(0.5 * 0.5 + 0.5 * 0.5 + 1.5 * 1.5 + 2.5 * 2.5 + 3.5 * 3.5);
  EXPECT_NEAR(objective1(e, s, measured).channels.at("dh"), held, 1e-12);
  EXPECT_NEAR(objective1(e, s, points(5)).channels.at("dh"), held, 1e-12);
  // A gauge with no finite reading has nothing to hold.
  const double nan = std::nan("");
  const Curve blank = curve("s.csv", {{"force", "", w}, {"dh", "", {nan, nan, nan, nan, nan}}});
  expect_curve_error([&] { objective1(e, blank, measured); }, {"channel 'dh'", "no loading point"});
}

TEST(Objective1, ACollapsedRunIsContinuedAtZeroForceToTheMeasuredEnd) {
  // The test holds 1 from w = 1 to 4; the run matches it, then collapses at w = 1.
  const Curve e = curve("e.csv", {{"time", "s", {0, 1, 2, 3, 4}}, {"force", "", {0, 1, 1, 1, 1}}, {"dv", "", {0, 1, 2, 3, 4}}});
  const Curve s = curve("s.csv", {{"time", "s", {0, 1}}, {"force", "", {0, 1}}, {"dv", "", {0, 1}}});
  EXPECT_DOUBLE_EQ(objective1(e, s, points(5)).fitness, 0.0);  // the shared window alone: a perfect score
  const auto ends = envelope_ends(e);
  ASSERT_EQ(ends.size(), 1u);
  EXPECT_EQ(ends.at("dv"), 4.0);
  const Curve c = continued_after_collapse(s, ends);
  // zero from the collapse on: w = 0..4 against 0, 1, 1, 1, 1
  EXPECT_DOUBLE_EQ(objective1(e, c, points(5)).fitness, 2.0);
  EXPECT_EQ(c.column("time").values, (std::vector<double>{0, 1, 1, 1}));  // other columns keep their last value
  // A run whose displacement came back before the collapse steps down at its largest displacement.
  const Curve back = curve("s.csv", {{"force", "", {0, 1, 1}}, {"dv", "", {0, 2, 1}}});
  const XYSeries env = loading_envelope(series(continued_after_collapse(back, ends), "dv", "force"));
  EXPECT_EQ(env.x, (std::vector<double>{0, 2, 4}));
  EXPECT_EQ(env.y, (std::vector<double>{0, 0, 0}));
  // When the run already reached the measured end only the step is added.
  EXPECT_EQ(continued_after_collapse(back, {{"dv", 1.5}}).rows(), 4u);
}
