// Analytic checks of the engine, each with its stated tolerance.
#include "demcal/dem/generators.hpp"
#include "demcal/dem/simulation.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace {

using namespace demcal::dem;
using test_support::kDeg;
constexpr double g = 9.81;

using test_support::box;

// A block b x h on a long fixed base; gravity tilted by `tilt` (equivalent to tilting the base).
Scene block_on_base(double b, double h, double tilt, double friction_deg, double kn = 1e9, double ks = 4e8) {
  Scene s;
  s.width = 0.2;
  s.gravity = Vec2(g * std::sin(tilt), -g * std::cos(tilt));
  JointMaterial m;
  m.normal_stiffness = kn;
  m.shear_stiffness = ks;
  m.friction_angle = friction_deg * kDeg;
  s.joint_groups["joint"] = m;
  s.default_joint_group = "joint";
  s.blocks = {box("base", -1, -0.1, 1, 0, true), box("block", -b / 2, 0, b / 2, h, false)};
  s.solver.collapse_displacement = 10;
  return s;
}

using test_support::block_named;

TEST(Incline, SticksWhileTangentBelowFriction) {
  // Just below the limit (tan = 0.98 tan 30 deg) the block must come to rest (equilibrium). It
  // slips a few micrometres while its contact force builds up from zero at the start, then holds:
  // under 0.1 mm in total, against more than 1 mm in the same time at 1.02 of the limit (below).
  const double tilt = std::atan(0.98 * std::tan(30 * kDeg));
  Scene s = block_on_base(0.2, 0.1, tilt, 30);
  s.solver.max_equilibrium_time = 2;
  const Recording r = simulate(s);
  EXPECT_EQ(r.status, RunStatus::completed) << r.message;
  EXPECT_LT(std::abs(block_named(r, "block").displacement.x()), 1e-4);
}

TEST(ContactDetection, BlockDroppedFromBeyondTheBroadPhaseSkinLandsAndRests) {
  // The broad phase keeps candidate pairs from a sweep with the search margin (1 mm) plus a skin
  // (a twentieth of the smallest block, 5 mm here) and sweeps again once a block has moved a
  // quarter of the skin. A block starting 30 mm above the base is not a candidate at first; it must
  // still find the base, come to rest on it (equilibrium) and press it by its weight only.
  Scene s = block_on_base(0.2, 0.1, 0, 30);
  for (auto& v : s.blocks[1].vertices) v.y() += 0.03;
  s.solver.max_equilibrium_time = 5;
  const Recording r = simulate(s);
  EXPECT_EQ(r.status, RunStatus::completed) << r.message;
  const double closure = 2000 * 0.1 * g / 1e9;  // W / (kn A) = ρ h g / kn, about 2 um
  EXPECT_NEAR(block_named(r, "block").displacement.y(), -0.03 - closure, 0.1 * closure);
}

// The automatic time step of a free block b x h (width 0.2 m) whose horizontal and vertical faces
// in full contact number `horizontal` and `vertical`: safety 0.5 x 2/omega with omega^2 =
// 2 (k_t/m + k_r/I), each face of length L adding k_t = w L (kn + ks) and k_r = w (kn L^3/12 +
// ks L d^2), where d is the face's distance from the centroid (normal springs about the face's
// middle, shear springs at d).
double block_time_step(double b, double h, int horizontal, int vertical, double kn, double ks, double density) {
  const double w = 0.2, m = density * w * b * h, inertia = m * (b * b + h * h) / 12;
  const double k_t = w * (kn + ks) * (horizontal * b + vertical * h);
  const double k_r = w * (horizontal * (kn * b * b * b / 12 + ks * b * h * h / 4) +
                          vertical * (kn * h * h * h / 12 + ks * h * b * b / 4));
  return 0.5 * 2 / std::sqrt(2 * (k_t / m + k_r / inertia));
}

TEST(TimeStep, CountsTheFacesInContactAsTheyComeIntoContact) {
  // A block dropped onto the base: before it lands all four faces count, after only its bottom.
  Scene s = block_on_base(0.2, 0.1, 0, 30);
  for (auto& v : s.blocks[1].vertices) v.y() += 0.03;
  s.solver.max_equilibrium_time = 5;
  ASSERT_EQ(s.solver.time_step_faces, "in_contact");  // the default
  const Recording landed = simulate(s);
  ASSERT_EQ(landed.status, RunStatus::completed) << landed.message;
  const double one_face = block_time_step(0.2, 0.1, 1, 0, 1e9, 4e8, 2000);
  EXPECT_NEAR(landed.time_step, one_face, 1e-12 * one_face);
  // A second block dropped onto the first: the first now touches with its top face too, and the
  // step shrinks to that of a block with two faces in contact.
  s.blocks.push_back(box("second", -0.1, 0.16, 0.1, 0.26, false));
  const Recording stacked = simulate(s);
  ASSERT_EQ(stacked.status, RunStatus::completed) << stacked.message;
  const double two_faces = block_time_step(0.2, 0.1, 2, 0, 1e9, 4e8, 2000);
  EXPECT_NEAR(stacked.time_step, two_faces, 1e-12 * two_faces);
  EXPECT_NEAR(block_named(stacked, "second").displacement.y(), -0.06, 1e-4);
  // time_step_faces "all": every face of every block from the start.
  s.solver.time_step_faces = "all";
  const Recording all = simulate(s);
  ASSERT_EQ(all.status, RunStatus::completed) << all.message;
  const double four_faces = block_time_step(0.2, 0.1, 2, 2, 1e9, 4e8, 2000);
  EXPECT_NEAR(all.time_step, four_faces, 1e-12 * four_faces);
}

TEST(Incline, SlidesJustAboveFriction) {
  Scene s = block_on_base(0.2, 0.1, std::atan(1.02 * std::tan(30 * kDeg)), 30);
  s.solver.max_equilibrium_time = 2;
  const Recording r = simulate(s);
  EXPECT_EQ(r.status, RunStatus::step_limit);
  EXPECT_GT(block_named(r, "block").displacement.x(), 1e-3);
}

TEST(Incline, SlidesWithCoulombAcceleration) {
  // tan(40 deg) > tan(30 deg): a = g (sin 40 - tan 30 cos 40) within 1 %, no damping.
  Scene s = block_on_base(0.2, 0.1, 40 * kDeg, 30);
  s.solver.local_damping = 0;
  s.solver.max_equilibrium_time = 0.5;
  const Recording r = simulate(s);
  EXPECT_EQ(r.status, RunStatus::step_limit);
  const double t = r.steps * r.time_step;
  const double expected = g * (std::sin(40 * kDeg) - std::tan(30 * kDeg) * std::cos(40 * kDeg));
  const double measured = 2 * block_named(r, "block").displacement.x() / (t * t);
  std::printf("incline: a measured %.5f m/s^2, analytic %.5f m/s^2\n", measured, expected);
  EXPECT_NEAR(measured, expected, 0.01 * expected);
}

// Top block pressed on a fixed block by a force F (and optionally a couple M), no gravity.
Recording pressed_joint(int points, double force, double moment) {
  Scene s;
  s.width = 0.2;
  s.gravity = Vec2::Zero();
  JointMaterial m;
  m.normal_stiffness = 1e9;
  m.shear_stiffness = 4e8;
  m.friction_angle = 40 * kDeg;
  s.joint_groups["joint"] = m;
  s.default_joint_group = "joint";
  s.contact.points_per_joint = points;
  s.blocks = {box("bottom", -0.1, -0.1, 0.1, 0, true), box("top", -0.1, 0, 0.1, 0.1, false)};
  s.loading.constant_forces.push_back({"top", Vec2(0, -force), Vec2(0, 0.05)});
  if (moment != 0) {  // a pure couple: two opposite vertical forces 0.1 m apart
    s.loading.constant_forces.push_back({"top", Vec2(0, -moment / 0.1), Vec2(0.05, 0.1)});
    s.loading.constant_forces.push_back({"top", Vec2(0, moment / 0.1), Vec2(-0.05, 0.1)});
  }
  s.solver.equilibrium_ratio = 1e-9;
  s.solver.max_equilibrium_time = 2;
  return simulate(s);
}

TEST(Joint, ClosureUnderForceIsForceOverStiffnessTimesArea) {
  const double force = 1e4, area = 0.2 * 0.2;
  const Recording r = pressed_joint(15, force, 0);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double closure = -block_named(r, "top").displacement.y();
  EXPECT_NEAR(closure, force / (1e9 * area), 0.01 * force / (1e9 * area));
}

TEST(Joint, RotationalStiffnessMatchesDiscreteNodes) {
  // k_rot = kn b L^3 / 12 (1 + 2 / (n - 1)^2) for n nodes with half shares at the ends.
  const double length = 0.2, width = 0.2, force = 1e4, moment = 20;  // small enough that no node opens
  for (int n : {2, 3, 5, 15}) {
    const Recording r = pressed_joint(n, force, moment);
    ASSERT_EQ(r.status, RunStatus::completed) << r.message;
    const double rotation = -block_named(r, "top").rotation;  // the couple turns clockwise
    const double expected = 1e9 * width * std::pow(length, 3) / 12 * (1 + 2.0 / ((n - 1) * (n - 1)));
    std::printf("n = %2d: rotational stiffness %.6g N m/rad, analytic %.6g\n", n, moment / rotation, expected);
    EXPECT_NEAR(moment / rotation, expected, 0.01 * expected) << n << " nodes";
  }
}

// Tips (collapses) or stands at a fixed tilt.
RunStatus tilt_block(double tan_tilt) {
  const double b = 0.1, h = 0.3;
  Scene s = block_on_base(b, h, std::atan(tan_tilt), 60, 1e10, 4e9);
  s.solver.collapse_displacement = 0.05;
  s.solver.max_equilibrium_time = 3;
  // Standing 2 % from the limit leaves the resultant 1 mm from the toe, where the last contact
  // node settles slowly: a ratio of 1e-4 separates standing from tipping without ambiguity.
  s.solver.equilibrium_ratio = 1e-4;
  const Recording r = simulate(s);
  std::printf("tilt tan %.4f: %s (%s)\n", tan_tilt, to_string(r.status).c_str(), r.message.c_str());
  return r.status;
}

TEST(Tipping, BlockTipsAtTanEqualsWidthOverHeight) {
  // b / h = 1/3: stands at 2 % below, tips at 2 % above.
  const double critical = 0.1 / 0.3;
  EXPECT_EQ(tilt_block(0.98 * critical), RunStatus::completed);
  EXPECT_EQ(tilt_block(1.02 * critical), RunStatus::collapsed);
}

TEST(SemicircularArch, StandsAtMilankovitchMarginCollapsesBelow) {
  // Minimum thickness t/R = 0.1075 (radial joints, rigid, no sliding): 31 voussoirs, 70 deg, kn 1e11.
  SemicircularArchOptions o;
  o.thickness_ratio = 0.115;
  const Recording stands = simulate(make_semicircular_arch(o));
  EXPECT_EQ(stands.status, RunStatus::completed) << stands.message;
  o.thickness_ratio = 0.100;
  const Recording falls = simulate(make_semicircular_arch(o));
  EXPECT_EQ(falls.status, RunStatus::collapsed) << falls.message;
}

}  // namespace
