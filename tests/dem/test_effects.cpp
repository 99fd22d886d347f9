// The engine's effects (docs/engine.md), each against a closed-form answer; tolerances are stated
// with their reasons. Then the effect options in scene files, parameters and the registry.
#include "demcal/dem/effects.hpp"
#include "demcal/dem/generators.hpp"
#include "demcal/dem/simulation.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <unistd.h>

namespace {

using namespace demcal::dem;
using test_support::kDeg;
constexpr double kWidth = 0.2, kLength = 0.2, kArea = kWidth * kLength;  // the joint: 0.2 m x 0.2 m

using test_support::box;

using test_support::block_named;

// A 0.2 x 0.1 m block ("top", 8 kg) on a fixed base, joint 0.2 m long, 0.2 m wide; kn 1e9, ks 4e8.
Scene block_on_base(double friction_deg = 30) {
  Scene s;
  s.width = kWidth;
  JointMaterial m;
  m.normal_stiffness = 1e9;
  m.shear_stiffness = 4e8;
  m.friction_angle = friction_deg * kDeg;
  s.joint_groups["joint"] = m;
  s.default_joint_group = "joint";
  s.blocks = {box("base", -0.5, -0.1, 0.5, 0, true), box("top", -0.1, 0, 0.1, 0.1, false)};
  s.solver.collapse_displacement = 1;
  return s;
}

// Displacement control of the top block: an actuator at `point` pushing (or pulling) along
// `direction`, and a gauge at the same point along it.
void actuate(Scene& s, const Vec2& point, const Vec2& direction, double velocity, double travel, double stiffness,
             bool compression_only = true) {
  s.loading.type = "point";
  s.loading.block = "top";
  s.loading.point = point;
  s.loading.direction = direction;
  s.loading.velocity = velocity;
  s.loading.max_displacement = travel;
  s.loading.stiffness = stiffness;
  s.loading.compression_only = compression_only;
  s.loading.record_interval = travel / 400;
  s.solver.max_time = travel / velocity * 1.5 + 2;
  s.gauges = {{"along", "top", point, direction}};
}

// Pressing the top block down on the base, no gravity: the gauge reads the joint closure. The
// travel takes 10 s, against the block's natural period of about 3 ms on the joint: the local
// damping, which cannot damp ringing while the block keeps moving one way, then leaves the
// actuator force within 0.2 % of the joint force (measured on the plain joint: 10 % at 0.2 s of
// loading, 1 % at 2 s, 0.1 % at 20 s; the ringing scales with the loading speed).
Scene pressed(double travel, double stiffness = 1e9) {
  Scene s = block_on_base();
  s.gravity = Vec2::Zero();
  actuate(s, Vec2(0, 0.1), Vec2(0, -1), travel / 10, travel, stiffness);
  return s;
}

TEST(JointClosure, PressedBlockFollowsTheHyperbola) {
  // Fn = kn A d / (1 - d / dmax) up to 3/4 of dmax, then the tangent 16 kn A continues linearly.
  // 1 %: the recorded force is the actuator spring's, within 0.2 % of the joint's (see pressed()).
  const double dmax = 1e-4, kn = 1e9;
  Scene s = pressed(0.9 * dmax);
  set_parameter(s, "closure_max", dmax);
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  int checked = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    const double d = r.gauge_values[0][i];
    if (d < 0.1 * dmax) continue;
    const double dc = 0.75 * dmax;
    const double expected = d <= dc ? kn * kArea * d / (1 - d / dmax)
                                    : kn * kArea * dc / (1 - dc / dmax) + 16 * kn * kArea * (d - dc);
    EXPECT_NEAR(r.force[i], expected, 0.01 * expected) << "closure " << d;
    ++checked;
  }
  EXPECT_GT(checked, 100);
  // The largest contact stress reported is the joint's uniform stress at the end of the travel.
  EXPECT_NEAR(r.max_normal_stress, r.peak_force / kArea, 0.01 * r.peak_force / kArea);
  EXPECT_LT(r.start_normal_stress, 0.02 * r.max_normal_stress);  // the first row: barely touched
  EXPECT_EQ(r.joints.size(), 1u);
  EXPECT_EQ(r.joints.front().max_normal_stress, r.max_normal_stress);
  // Against the linear law at the same travel: the stiffened joint carries far more.
  const Recording plain = simulate(pressed(0.9 * dmax));
  EXPECT_GT(r.peak_force, 3 * plain.peak_force);
}

TEST(JointClosure, TheTimeStepTakesTheCapsOrFollowsTheNodesTangentStiffness) {
  // The block pressed to half its maximum closure, with shear stiffening: every node of the joint at
  // closure d has the tangent kn / (1 - d/dmax)^2 and the shear stiffness ks (1 + s / stress). With
  // time_step_stiffening "nodes" the automatic step is the bound of docs/engine.md with the bottom
  // face at kn and ks plus each node's excess over them (at its tributary length and moment arm),
  // and the actuator spring: 0.5 x 2/omega, omega^2 = 2 (k_t/m + k_r/I). 1e-3: the nodes sit half
  // their penetration below the face and the block tilts by round-off, which moves the arms by less.
  const double dmax = 1e-4, kn = 1e9, ks = 4e8, stiffening_stress = 1e5, actuator = 1e9;
  Scene s = pressed(0.5 * dmax, actuator);
  set_parameter(s, "closure_max", dmax);
  set_parameter(s, "shear_stiffening_stress", stiffening_stress);
  ASSERT_EQ(s.solver.time_step_stiffening, "caps");  // the default
  const Recording capped = simulate(s);
  ASSERT_EQ(capped.status, RunStatus::completed) << capped.message;
  s.solver.time_step_stiffening = "nodes";
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double d = r.gauge_values[0].back(), open = 1 - d / dmax;
  ASSERT_GT(d, 0.4 * dmax);
  const double excess_kn = kn * (1 / (open * open) - 1);
  const double excess_ks = ks * std::min(15.0, kn * d / open / stiffening_stress);
  const int nodes = s.contact.points_per_joint;
  const double spacing = kLength / (nodes - 1);
  double second_moment = 0;  // sum of tributary length x^2 over the nodes, x from the face's middle
  for (int k = 0; k < nodes; ++k) {
    const double x = -kLength / 2 + k * spacing, length = (k == 0 || k == nodes - 1 ? 0.5 : 1.0) * spacing;
    second_moment += length * x * x;
  }
  const double h = 0.1, arm = h / 2, mass = 2000 * kWidth * kLength * h, inertia = mass * (kLength * kLength + h * h) / 12;
  const double k_t = kWidth * kLength * (kn + ks + excess_kn + excess_ks) + actuator;
  const double k_r = kWidth * (kn * std::pow(kLength, 3) / 12 + ks * kLength * arm * arm + excess_kn * second_moment +
                               excess_ks * kLength * arm * arm);
  const double expected = 0.5 * 2 / std::sqrt(2 * (k_t / mass + k_r / inertia));
  EXPECT_NEAR(r.time_step, expected, 1e-3 * expected);
  // "caps": the face at 16 kn and 16 ks, whatever the closure, 1.4 x shorter here (the actuator's
  // spring weighs as much as the capped joint in translation).
  const double capped_t = kWidth * kLength * 16 * (kn + ks) + actuator;
  const double capped_r = kWidth * 16 * (kn * std::pow(kLength, 3) / 12 + ks * kLength * arm * arm);
  const double capped_step = 0.5 * 2 / std::sqrt(2 * (capped_t / mass + capped_r / inertia));
  EXPECT_NEAR(capped.time_step, capped_step, 1e-12 * capped_step);
  EXPECT_GT(r.time_step, 1.3 * capped_step);
  EXPECT_NEAR(capped.peak_force, r.peak_force, 0.01 * r.peak_force);  // the same joint, pressed alike
}

TEST(FrictionSoftening, SlidingResistanceFallsFromPeakToResidualOverTheSlipLength) {
  // A weighted block pushed along its base at the joint's height (no overturning moment, so every
  // node carries W/n and slides together). Slip = displacement - elastic shear F / (ks A). Resistance
  // W (tan phi_r + (tan phi_p - tan phi_r) max(0, 1 - slip / s)). 1.5 % of the peak: the block
  // accelerates a little as friction falls, and the actuator force carries that inertia; 10 s of
  // loading keeps the ringing small (see pressed()).
  const double peak = 35, residual = 20, length = 2e-3;
  Scene s = block_on_base(peak);
  set_parameter(s, "friction_residual_deg", residual);
  set_parameter(s, "slip_softening", length);
  actuate(s, Vec2(-0.1, 0), Vec2(1, 0), 3e-4, 3e-3, 1e8);
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double weight = 2000 * kWidth * 0.02 * 9.81;
  const double tan_p = std::tan(peak * kDeg), tan_r = std::tan(residual * kDeg);
  int checked = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    const double slip = r.gauge_values[0][i] - r.force[i] / (4e8 * kArea);
    if (slip < 0.05 * length) continue;
    const double expected = weight * (tan_r + (tan_p - tan_r) * std::max(0.0, 1 - slip / length));
    EXPECT_NEAR(r.force[i], expected, 0.015 * weight * tan_p) << "slip " << slip;
    ++checked;
  }
  EXPECT_GT(checked, 200);
  EXPECT_NEAR(r.peak_force, weight * tan_p, 0.015 * weight * tan_p);
  std::printf("softening: peak %.3f N (W tan phi_p %.3f), end %.3f N (W tan phi_r %.3f)\n", r.peak_force,
              weight * tan_p, r.force.back(), weight * tan_r);
}

// `read` must throw a SceneError whose message holds `needle`.
template <typename Read>
void expect_scene_error(Read read, const std::string& needle) {
  try {
    read();
    ADD_FAILURE() << "accepted; expected an error with " << needle;
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}
void expect_invalid(Scene s, const std::string& needle) {
  expect_scene_error([&] { s.Validate("s.json"); }, needle);
}

// The residual given as the loss from the peak: it follows the friction angle whichever of the two is
// set first, the law softens to friction_deg - friction_loss_deg (the same curve, force for force,
// as that residual given as an angle), and the two forms exclude each other.
TEST(FrictionSoftening, TheLossFromThePeakFollowsTheFrictionAngle) {
  Scene s = block_on_base(35);
  set_parameter(s, "slip_softening", 2e-3);
  set_parameter(s, "friction_loss_deg", 15);
  set_parameter(s, "friction_deg", 30);  // after the loss: the residual moves with it
  const JointMaterial& m = s.joint_groups.begin()->second;
  EXPECT_EQ(m.residual_friction(), 30 * kDeg - 15 * kDeg);
  EXPECT_NEAR(get_parameter(s, "friction_loss_deg"), 15, 1e-12);
  EXPECT_NO_THROW(s.Validate("s.json"));

  actuate(s, Vec2(-0.1, 0), Vec2(1, 0), 3e-4, 3e-3, 1e8);
  Scene as_angle = s;
  JointMaterial& angle_form = as_angle.joint_groups.begin()->second;
  angle_form.friction_residual = angle_form.residual_friction();
  angle_form.friction_loss = 0;
  const Recording by_loss = simulate(s), by_angle = simulate(as_angle);
  ASSERT_EQ(by_loss.status, RunStatus::completed) << by_loss.message;
  EXPECT_EQ(by_loss.force, by_angle.force);
  EXPECT_LT(by_loss.force.back(), 0.7 * by_loss.peak_force);  // softened: tan 15 deg / tan 30 deg = 0.46

  // Through JSON: the loss is written as the loss, and a file with both forms is refused.
  const nlohmann::json j = scene_to_json(s);
  const nlohmann::json& group = j["joint_groups"].begin().value();
  EXPECT_TRUE(group.contains("friction_loss_deg"));
  EXPECT_FALSE(group.contains("friction_residual_deg"));
  EXPECT_EQ(scene_hash(scene_from_json(j, "roundtrip")), scene_hash(s));
  nlohmann::json both = j;
  both["joint_groups"].begin().value()["friction_residual_deg"] = 10;
  expect_scene_error([&] { scene_from_json(both, "both.json"); },  // validates what it reads
                     "set friction_residual_deg or friction_loss_deg, not both (got 10 and 15");
  // Setting one form clears the other; a loss beyond the friction angle is named with its value.
  set_parameter(s, "friction_residual_deg", 12);
  EXPECT_EQ(s.joint_groups.begin()->second.friction_loss, 0);
  EXPECT_EQ(s.joint_groups.begin()->second.residual_friction(), 12 * kDeg);
  set_parameter(s, "friction_loss_deg", 40);
  EXPECT_EQ(s.joint_groups.begin()->second.friction_residual, 0);
  expect_invalid(s, "friction_loss_deg: must be in [0, friction_deg = 30] degrees, got 40");
}

// The joint's slip report (JointReport::slip), through the plain law's loop and through the node
// loop of a group with an effect: a block pushed along its base slides by its travel less the
// joint's elastic shear F / (ks A). Each step's plastic slip is the part of that step's shear
// displacement the limit does not take, so the two agree to round-off (measured: 9 digits); 1e-6
// leaves room for the block's inertia in the actuator force.
TEST(JointReport, SlipIsTheTravelLessTheElasticShear) {
  for (const bool softening : {false, true}) {
    Scene s = block_on_base(30);
    if (softening) {
      set_parameter(s, "friction_residual_deg", 20.0);
      set_parameter(s, "slip_softening", 2e-3);
    }
    actuate(s, Vec2(-0.1, 0), Vec2(1, 0), 3e-4, 3e-3, 1e8);
    const Recording r = simulate(s);
    ASSERT_EQ(r.status, RunStatus::completed) << r.message;
    ASSERT_EQ(r.joints.size(), 1u);
    const double expected = r.gauge_values[0].back() - r.force.back() / (4e8 * kArea);
    EXPECT_NEAR(r.joints[0].slip, expected, 1e-6 * expected) << "softening " << softening;
    EXPECT_TRUE(r.joints[0].sliding);
  }
}

TEST(Cohesion, BondedBlockBreaksAtCohesionTimesAreaPlusFriction) {
  // Pushed along the joint: every node reaches c a + tan(phi) n at once, so the breaking load is
  // c A + W tan(phi) and afterwards the plain W tan(phi). 1 %: the recording interval (0.25 um of
  // travel, 0.3 % of the load) and 10 s of quasi-static loading (see pressed()).
  const double c = 2e4, phi = 30;
  Scene s = block_on_base(phi);
  set_parameter(s, "cohesion", c);
  actuate(s, Vec2(-0.1, 0), Vec2(1, 0), 1e-5, 1e-4, 1e9);
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double weight = 2000 * kWidth * 0.02 * 9.81, friction = weight * std::tan(phi * kDeg);
  std::printf("cohesion: breaking load %.2f N (c A + W tan phi = %.2f N), end %.2f N\n", r.peak_force,
              c * kArea + friction, r.force.back());
  EXPECT_NEAR(r.peak_force, c * kArea + friction, 0.01 * (c * kArea + friction));
  EXPECT_NEAR(r.force.back(), friction, 0.03 * friction);  // 3 %: still ringing from the brittle drop
  // The same block without cohesion never carries more than friction.
  Scene dry = block_on_base(phi);
  actuate(dry, Vec2(-0.1, 0), Vec2(1, 0), 1e-5, 1e-4, 1e9);
  EXPECT_LT(simulate(dry).peak_force, 1.02 * friction);
}

TEST(Cohesion, BondedBlockPulledOffAtTensileStrengthTimesAreaPlusWeight) {
  // Pulled straight up at the centroid: every node reaches -ft a at once; breaking load ft A + W.
  // The cohesion keeps the Coulomb limit c A + tan(phi) Fn positive under that tension (with c = 0
  // a bond cannot hold tension at all). 1 %: as above.
  const double ft = 1e4;
  Scene s = block_on_base();
  set_parameter(s, "tensile_strength", ft);
  set_parameter(s, "cohesion", 1e5);
  actuate(s, Vec2(0, 0.05), Vec2(0, 1), 5e-6, 5e-5, 1e9, false);
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double weight = 2000 * kWidth * 0.02 * 9.81;
  std::printf("tension: breaking load %.2f N (ft A + W = %.2f N)\n", r.peak_force, ft * kArea + weight);
  EXPECT_NEAR(r.peak_force, ft * kArea + weight, 0.01 * (ft * kArea + weight));
  EXPECT_LT(r.force.back(), 0.5 * r.peak_force);  // broken for good
}

TEST(CrushingCap, ForceCappedAtStrengthTimesAreaThenFalling) {
  // Elastic up to fc A (closure fc / kn = 1 mm), then the strength falls linearly to zero over
  // crushing_softening of plastic closure: F = fc A (1 - d / s) / (1 - fc / (kn s)) for closure d.
  // 1 %: quasi-static loading through a stiff actuator (1e9 N/m against a softening slope of 1e7).
  // The block is held level: a softening joint under a free block localises (one side crushes, the
  // block tips), which is the toe crushing of a wall, not this closed form.
  const double fc = 1e6, soft = 5e-3, kn = 1e9;
  Scene s = pressed(4e-3, 1e9);
  s.blocks[1].fixed_rotation = true;
  set_parameter(s, "compressive_strength", fc);
  set_parameter(s, "crushing_softening", soft);
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  EXPECT_NEAR(r.peak_force, fc * kArea, 0.01 * fc * kArea);
  int checked = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    const double d = r.gauge_values[0][i];
    if (d < 1.05 * fc / kn) continue;
    const double expected = fc * kArea * (1 - d / soft) / (1 - fc / (kn * soft));
    EXPECT_NEAR(r.force[i], expected, 0.01 * fc * kArea) << "closure " << d;
    ++checked;
  }
  EXPECT_GT(checked, 200);
  std::printf("crushing: peak %.1f N (fc A = %.1f N), end %.1f N at %.2f mm\n", r.peak_force, fc * kArea,
              r.force.back(), 1e3 * r.gauge_values[0].back());
  // Without softening the cap is a plateau.
  Scene flat = pressed(3e-3, 1e9);
  flat.blocks[1].fixed_rotation = true;
  set_parameter(flat, "compressive_strength", fc);
  const Recording p = simulate(flat);
  ASSERT_EQ(p.status, RunStatus::completed) << p.message;
  EXPECT_NEAR(p.force.back(), fc * kArea, 0.01 * fc * kArea);
  EXPECT_NEAR(p.max_normal_stress, fc, 1e-6 * fc);  // the capped stress, not the elastic trial's
}

// The joint's elastic shear stiffness in N/m: the block of block_on_base() under its weight alone
// (normal stress W/A, 1962 Pa), pushed along its base at the joint's height so that every node
// carries W/n, with `stress` (0: off) as the stress that doubles ks. The slope of force against
// displacement (least squares) while the force stays between 10 and 70 % of W tan(phi), where no
// node slides.
double elastic_shear_stiffness(double stress) {
  Scene s = block_on_base(30);
  if (stress > 0) set_parameter(s, "shear_stiffening_stress", stress);
  actuate(s, Vec2(-0.1, 0), Vec2(1, 0), 4e-7, 4e-6, 1e8);
  const Recording r = simulate(s);
  EXPECT_EQ(r.status, RunStatus::completed) << r.message;
  const double limit = 2000 * kWidth * 0.02 * 9.81 * std::tan(30 * kDeg);
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    if (r.force[i] < 0.1 * limit || r.force[i] > 0.7 * limit) continue;
    const double x = r.gauge_values[0][i], y = r.force[i];
    n += 1, sx += x, sy += y, sxx += x * x, sxy += x * y;
  }
  EXPECT_GT(n, 10) << "rows in the elastic range";
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

TEST(ShearStiffening, ShearStiffnessGrowsWithTheNormalStressUpToItsCap) {
  // ks A (1 + s / stress) with s = W/A: 4 x ks A at a third of the joint's stress; 16 x (the cap)
  // far below it. 2 %: the least-squares slope of quasi-static loading (10 s through a soft actuator).
  const double ks_area = 4e8 * kArea, stress = 2000 * 0.1 * 9.81;  // W/A = rho h g
  EXPECT_NEAR(elastic_shear_stiffness(0), ks_area, 0.02 * ks_area);
  EXPECT_NEAR(elastic_shear_stiffness(stress / 3), 4 * ks_area, 0.02 * 4 * ks_area);
  EXPECT_NEAR(elastic_shear_stiffness(stress / 1000), 16 * ks_area, 0.02 * 16 * ks_area);
}

TEST(SupportCompliance, SupportMovesByThrustOverSpringStiffness) {
  // A block pushed by a constant 1 kN against a support on a 1e7 N/m horizontal spring (vertical
  // and rotation held): at equilibrium the support has moved F / kx = 0.1 mm. 0.5 %: equilibrium
  // is reached to a ratio of 1e-7 of the load; nothing else enters.
  const double force = 1000, kx = 1e7;
  Scene s;
  s.width = kWidth;
  s.gravity = Vec2::Zero();
  s.joint_groups["joint"] = JointMaterial{};
  s.blocks = {box("pusher", -0.1, 0, 0.1, 0.1, false), box("support", 0.1, 0, 0.3, 0.1, true)};
  s.blocks[1].support_kx = kx;
  s.loading.constant_forces.push_back({"pusher", Vec2(force, 0), Vec2(-0.1, 0.05)});
  s.solver.equilibrium_ratio = 1e-7;
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const BlockState& support = block_named(r, "support");
  EXPECT_NEAR(support.displacement.x(), force / kx, 0.005 * force / kx);
  EXPECT_EQ(support.displacement.y(), 0.0);
  EXPECT_EQ(support.rotation, 0.0);
  EXPECT_TRUE(support.fixed);
  // Rigid (the default): the support does not move at all.
  s.blocks[1].support_kx = 0;
  EXPECT_EQ(block_named(simulate(s), "support").displacement.x(), 0.0);
}

TEST(JointGap, NoForceUntilTheGapClosesThenThePlainLaw) {
  // Uniform opening g: F = 0 for d < g, then kn A (d - g). 1 % of the final force: before contact
  // the actuator only drives the free block's 8 kg at constant speed.
  const double g = 2e-4, kn = 1e9;
  Scene s = pressed(4e-4);
  s.joint_gap = {"top/base", g, 0};  // uniform
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  const double scale = kn * kArea * (4e-4 - g);
  int before = 0, after = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    const double d = r.gauge_values[0][i];
    if (d < 0.95 * g) {
      EXPECT_LT(r.force[i], 0.01 * scale) << "closure " << d;
      ++before;
    } else if (d > 1.05 * g) {
      EXPECT_NEAR(r.force[i], kn * kArea * (d - g), 0.01 * scale) << "closure " << d;
      ++after;
    }
  }
  EXPECT_GT(before, 100);
  EXPECT_GT(after, 100);
}

TEST(JointGap, WedgeClosesFromTheIntradosEnd) {
  // A level joint: the intrados end is the left one. Opening 0 there, g at the right, the block
  // held level: contact over a growing share d / g of the length, F = kn w L d^2 / (2 g); once
  // closed everywhere F = kn w L (d - g / 2). 101 nodes: the trapezoid rule is exact for the linear
  // profile after closure (1 %) and within 2 % of the quadratic one before it.
  const double g = 4e-4, kn = 1e9;
  Scene s = pressed(6e-4);
  s.contact.points_per_joint = 101;
  s.blocks[1].fixed_rotation = true;
  s.joint_gap = {"base/top", g, 1};  // closed at the intrados
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  int checked = 0;
  for (std::size_t i = 0; i < r.force.size(); ++i) {
    const double d = r.gauge_values[0][i];
    if (d > 1.02 * g) {
      const double expected = kn * kWidth * kLength * (d - g / 2);
      EXPECT_NEAR(r.force[i], expected, 0.01 * expected) << "closure " << d;
      ++checked;
    } else if (d > 0.4 * g && d < 0.9 * g) {
      const double expected = kn * kWidth * kLength * d * d / (2 * g);
      EXPECT_NEAR(r.force[i], expected, 0.02 * expected) << "closure " << d;
      ++checked;
    }
  }
  EXPECT_GT(checked, 150);
}

TEST(BoundaryRestraint, MomentEqualsSpringTimesRotation) {
  // A free block under a pure couple M on a rotational spring kr: rotation M / kr = 1 mrad. 0.5 %:
  // the forces keep their world direction while the block turns, a relative error of 1 - cos(1e-3).
  const double kr = 1e5, moment = 100;
  Scene s;
  s.width = kWidth;
  s.gravity = Vec2::Zero();
  s.joint_groups["joint"] = JointMaterial{};
  s.blocks = {box("beam", -0.1, 0, 0.1, 0.1, false)};
  s.blocks[0].beam_kr = kr;
  s.blocks[0].fixed_rotation = true;  // released by the spring
  s.loading.constant_forces = {{"beam", Vec2(0, -moment / 0.1), Vec2(0.05, 0.1)},
                               {"beam", Vec2(0, moment / 0.1), Vec2(-0.05, 0.1)}};
  s.solver.equilibrium_ratio = 1e-8;
  const Recording r = simulate(s);
  ASSERT_EQ(r.status, RunStatus::completed) << r.message;
  EXPECT_NEAR(-block_named(r, "beam").rotation, moment / kr, 0.005 * moment / kr);
}

TEST(Effects, EveryEffectOffKeepsTheSceneTextAndHash) {
  const Scene arch = make_arch(ArchOptions{});
  const nlohmann::json j = scene_to_json(arch);
  for (const char* key : {"closure_max", "slip_softening", "friction_residual_deg", "friction_loss_deg", "cohesion",
                          "tensile_strength", "compressive_strength", "crushing_softening"})
    EXPECT_FALSE(j["joint_groups"]["arch_joints"].contains(key)) << key;
  EXPECT_FALSE(j.contains("joint_gap"));
  for (const auto& b : j["blocks"]) EXPECT_FALSE(b.contains("support_kx") || b.contains("beam_kr"));
  // The hashes of the default scenes: unchanged by the effects' options, changed only when the
  // default scene's physics changed (the time step over the faces in contact, written always).
  EXPECT_EQ(scene_hash(arch), "a25af76dc440fb4c");
  EXPECT_EQ(scene_hash(make_wall(WallOptions{})), "493cdb47e1bf8088");
}

TEST(Effects, OptionsRoundTripThroughJsonAndChangeTheHash) {
  Scene s = make_arch(ArchOptions{});
  const std::string plain = scene_hash(s);
  set_parameter(s, "closure_max", 1e-4);
  set_parameter(s, "arch_joints.friction_residual_deg", 20);
  set_parameter(s, "arch_joints.slip_softening", 1e-3);
  set_parameter(s, "cohesion", 1e4);
  set_parameter(s, "tensile_strength", 5e3);
  set_parameter(s, "compressive_strength", 2e7);
  set_parameter(s, "crushing_softening", 1e-3);
  set_parameter(s, "abutment_right.support_kx", 1e8);
  set_parameter(s, "abutment_right.support_kr", 1e7);
  s.joint_gap.joint = "voussoir_9/voussoir_10";
  set_parameter(s, "gap_intrados", 0);
  set_parameter(s, "gap_extrados", 1e-3);
  set_parameter(s, "beam_kr", 1e6);  // the loaded voussoir
  const Scene back = scene_from_json(scene_to_json(s), "roundtrip");
  EXPECT_EQ(scene_hash(back), scene_hash(s));
  EXPECT_NE(scene_hash(s), plain);
  for (const auto& name : parameter_names(s)) EXPECT_DOUBLE_EQ(get_parameter(back, name), get_parameter(s, name)) << name;
  EXPECT_NEAR(get_parameter(back, "arch_joints.friction_residual_deg"), 20, 1e-12);
  EXPECT_EQ(get_parameter(back, "abutment_joints.slip_softening"), 0);
  EXPECT_EQ(get_parameter(back, "abutment_right.support_kx"), 1e8);
  EXPECT_EQ(get_parameter(back, "abutment_left.support_kx"), 0);
  EXPECT_EQ(get_parameter(back, "beam_kr"), 1e6);
  EXPECT_EQ(back.blocks[back.block_index("voussoir_5")].beam_kr, 1e6);
  EXPECT_EQ(get_parameter(back, "gap_extrados"), 1e-3);
}

TEST(JointGap, OpeningAndTaperSetTheEndsInEitherOrder) {
  Scene s = make_arch(ArchOptions{});
  s.joint_gap.joint = "voussoir_9/voussoir_10";
  // a wedge closed at the intrados; past 1 the taper means 1, so a search holds it on a range
  for (const double taper : {1.0, 1.3}) {
    Scene a = s, b = s;
    set_parameter(a, "gap_opening", 1e-3);
    set_parameter(a, "gap_taper", taper);
    set_parameter(b, "gap_taper", taper);
    set_parameter(b, "gap_opening", 1e-3);
    for (const Scene* x : {&a, &b}) {
      EXPECT_EQ(get_parameter(*x, "gap_intrados"), 0);
      EXPECT_EQ(get_parameter(*x, "gap_extrados"), 1e-3);
      EXPECT_EQ(get_parameter(*x, "gap_taper"), taper);
    }
  }
  set_parameter(s, "gap_opening", 2e-3);
  set_parameter(s, "gap_taper", -0.25);  // a quarter closed at the extrados end
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_intrados"), 2e-3);
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_extrados"), 1.5e-3);
  set_parameter(s, "gap_opening", 4e-3);  // the taper kept
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_extrados"), 3e-3);
  set_parameter(s, "gap_intrados", 1e-3);  // the other end kept: now the wider end is the extrados
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_opening"), 3e-3);
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_taper"), 1 - 1.0 / 3);
  EXPECT_DOUBLE_EQ(get_parameter(s, "gap_intrados"), 1e-3);
  // the same scene through either form in JSON
  nlohmann::json ends = scene_to_json(s);
  ends["joint_gap"] = {{"joint", "voussoir_9/voussoir_10"}, {"intrados", 1e-3}, {"extrados", 3e-3}};
  EXPECT_DOUBLE_EQ(get_parameter(scene_from_json(ends), "gap_taper"), 1 - 1.0 / 3);
  ends["joint_gap"]["taper"] = 0.5;
  EXPECT_THROW(scene_from_json(ends), SceneError);  // both forms at once
}

TEST(Effects, ValidateNamesTheKeyAndTheValue) {
  const Scene arch = make_arch(ArchOptions{});
  Scene s = arch;
  set_parameter(s, "arch_joints.slip_softening", 1e-3);
  set_parameter(s, "arch_joints.friction_residual_deg", 40);
  expect_invalid(s, "joint_groups.arch_joints.friction_residual_deg: must be in [0, friction_deg = 30.5] degrees, got 40");
  s = arch;
  set_parameter(s, "closure_max", 0.02);
  expect_invalid(s, "closure_max: must be at most 0.01");
  s = arch;
  set_parameter(s, "abutment_joints.cohesion", -5);
  expect_invalid(s, "joint_groups.abutment_joints.cohesion: must not be negative, got -5");
  s = arch;
  set_parameter(s, "compressive_strength", 2e9);
  expect_invalid(s, "compressive_strength: must be at most 1000000000");
  s = arch;
  set_parameter(s, "abutment_left.support_ky", -1);
  expect_invalid(s, "'abutment_left'.support_ky: must not be negative, got -1");
  s = arch;
  s.blocks[3].support_kx = 1e6;  // a voussoir is free
  expect_invalid(s, "apply to fixed blocks only");
  s = arch;
  s.joint_gap = {"voussoir_9/voussoir_11", 1e-4, 0};
  expect_invalid(s, "joint_gap.joint: blocks of 'voussoir_9/voussoir_11' share no edge");
  s.joint_gap = {"voussoir_9/nothing", 1e-4, 0};
  expect_invalid(s, "does not name two different blocks");
  s.joint_gap = {"voussoir_9/voussoir_10", 0.02, 0};
  expect_invalid(s, "joint_gap.opening: must be at most 0.01");
  s.joint_gap = {"voussoir_9/voussoir_10", 1e-3, -2.5};
  expect_invalid(s, "joint_gap.taper: must be in [-2, 2] (beyond 1 it equals 1), got -2.5");
  EXPECT_THROW(set_parameter(s, "gap_extrados", -1e-4), SceneError);  // an end has no sign to hold
  EXPECT_THROW(set_parameter(s, "voussoir_3.support_kx", 1), SceneError);   // a free block
  EXPECT_THROW(set_parameter(s, "abutment_left.beam_kr", 1), SceneError);   // a fixed block
  Scene no_gap = arch;
  EXPECT_THROW(set_parameter(no_gap, "gap_intrados", 1e-4), SceneError);
}

TEST(EffectRegistry, EveryEffectSwitchesOnAndRunsTheReferenceArch) {
  ASSERT_EQ(effect_registry().size(), 8u);
  EXPECT_THROW(find_effect("magic"), SceneError);
  ArchOptions o;
  o.max_displacement = 0.003;
  o.contacts_per_joint = 5;
  const Scene plain = make_arch(o);
  for (const Effect& effect : effect_registry()) {
    Scene s = plain;
    EXPECT_FALSE(effect_enabled(s, effect.name)) << effect.name;
    std::vector<std::string> targets;
    if (effect.target == EffectTarget::joint) targets = {"voussoir_9/voussoir_10"};
    if (effect.target == EffectTarget::support_blocks) targets = {"abutment_right"};
    const auto controls = enable_effect(s, effect.name, targets);
    EXPECT_TRUE(effect_enabled(s, effect.name)) << effect.name;
    EXPECT_NE(scene_hash(s), scene_hash(plain)) << effect.name;
    ASSERT_FALSE(controls.empty());
    const auto names = parameter_names(s);
    for (const auto& c : controls) EXPECT_NE(std::find(names.begin(), names.end(), c), names.end()) << c;
    for (const EffectParameter& p : effect.parameters) {
      EXPECT_LE(p.lower_bound, p.search_min) << p.name;
      EXPECT_LT(p.search_min, p.search_max) << p.name;
      EXPECT_LE(p.search_max, p.upper_bound) << p.name;
      EXPECT_GE(p.default_value, p.search_min) << p.name;
      EXPECT_LE(p.default_value, p.search_max) << p.name;
      EXPECT_FALSE(p.unit.empty());
    }
    const Recording r = simulate(s);
    std::printf("%-20s %-10s peak %.0f N (controls:", effect.name.c_str(), to_string(r.status).c_str(), r.peak_force);
    for (const auto& c : controls) std::printf(" %s", c.c_str());
    std::printf(")\n");
    EXPECT_TRUE(r.status == RunStatus::completed || r.status == RunStatus::collapsed) << effect.name << ": " << r.message;
  }
  Scene s = plain;
  EXPECT_EQ(enable_effect(s, "joint-closure", {"abutment_joints"}), std::vector<std::string>{"abutment_joints.closure_max"});
  EXPECT_EQ(get_parameter(s, "arch_joints.closure_max"), 0);
  EXPECT_THROW(enable_effect(s, "joint-gap"), SceneError);
  EXPECT_THROW(enable_effect(s, "support-compliance", {"voussoir_2"}), SceneError);
}

TEST(EffectRegistry, CompressiveStrengthIsSearchedBelowTheLargestContactStress) {
  const EffectParameter& strength = find_effect("crushing-cap").parameters.front();
  ASSERT_EQ(strength.name, "compressive_strength");
  ASSERT_EQ(strength.search_scale, SearchScale::peak_normal_stress);
  ResponseScales scales;
  scales.peak_normal_stress = 1.75e6;
  const EffectParameter scaled = scaled_search_range(strength, scales);
  EXPECT_DOUBLE_EQ(scaled.search_min, strength.scaled_min * 1.75e6);
  EXPECT_DOUBLE_EQ(scaled.search_max, strength.scaled_max * 1.75e6);
  EXPECT_LT(scaled.search_min, 1.75e6);  // the range brackets the stress reached
  EXPECT_GT(scaled.search_max, 1.75e6);
  // Never below the stress at the start of loading (the structure would crush before the test).
  scales.start_normal_stress = 0.5e6;
  EXPECT_DOUBLE_EQ(scaled_search_range(strength, scales).search_min, 0.5e6);
  EXPECT_DOUBLE_EQ(scaled_search_range(strength, scales).search_max, scaled.search_max);
  scales.start_normal_stress = 1e3;  // below the scaled minimum: no effect
  EXPECT_DOUBLE_EQ(scaled_search_range(strength, scales).search_min, scaled.search_min);
  scales.start_normal_stress = 0;
  // Unknown scale: the absolute range stays.
  EXPECT_EQ(scaled_search_range(strength, ResponseScales{}).search_min, strength.search_min);
  EXPECT_EQ(scaled_search_range(strength, ResponseScales{}).search_max, strength.search_max);
  // Clipped to the physical bounds.
  scales.peak_normal_stress = 1e12;
  EXPECT_EQ(scaled_search_range(strength, scales).search_max, strength.upper_bound);
  // A parameter without a scale is unchanged.
  const EffectParameter& softening = find_effect("crushing-cap").parameters.back();
  EXPECT_EQ(scaled_search_range(softening, scales).search_max, softening.search_max);
  EXPECT_EQ(scaled_range_words(softening, scales), "");
}

// A stress level (shear stiffening's doubling stress) scales like a strength but has no floor: a
// stress far below the one at the start of loading is a strong stiffening, not a crushed structure.
TEST(EffectRegistry, AStressLevelIsScaledWithoutTheStrengthsFloor) {
  const EffectParameter& stress = find_effect("shear-stiffening").parameters.front();
  ASSERT_EQ(stress.search_scale, SearchScale::stress_level);
  const ResponseScales scales{1e6, 0.5e6};  // peak, start
  const EffectParameter scaled = scaled_search_range(stress, scales);
  EXPECT_DOUBLE_EQ(scaled.search_min, stress.scaled_min * 1e6);
  EXPECT_LT(scaled.search_min, scales.start_normal_stress);
  EXPECT_DOUBLE_EQ(scaled.search_max, stress.scaled_max * 1e6);
  const std::string words = scaled_range_words(stress, scales);
  EXPECT_NE(words.find("x the largest contact stress of the base fit, 1e+06 Pa"), std::string::npos) << words;
  EXPECT_EQ(words.find("not below"), std::string::npos) << words;
  const std::string strength = scaled_range_words(find_effect("crushing-cap").parameters.front(), scales);
  EXPECT_NE(strength.find("not below the largest at the start of loading, 5e+05 Pa"), std::string::npos) << strength;
  EXPECT_EQ(scaled_range_words(stress, ResponseScales{}), "");  // unknown scale: the absolute range
}

using test_support::run_demcal;

TEST(EffectFlags, SceneCommandWritesEveryOption) {
  const auto dir = std::filesystem::temp_directory_path() / ("demcal_effects_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string arch = (dir / "arch.json").string(), wall = (dir / "wall.json").string();
  auto r = run_demcal("scene arch --closure-max 1e-4 --friction-residual-deg 20 --slip-softening 2e-3 --cohesion 1e4 "
                      "--tensile-strength 5e3 --compressive-strength 2e7 --crushing-softening 1e-3 --support-kx 1e8 "
                      "--support-kr 1e7 --support-blocks abutment_right --gap-joint voussoir_9/voussoir_10 "
                      "--gap-extrados 1e-3 --beam-kr 1e6 -o " + arch);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Scene a = load_scene(arch);
  for (const auto& group : {"arch_joints", "abutment_joints"}) {
    const JointMaterial& m = a.joint_groups.at(group);
    EXPECT_EQ(m.closure_max, 1e-4);
    EXPECT_NEAR(m.friction_residual, 20 * kDeg, 1e-12);
    EXPECT_EQ(m.slip_softening, 2e-3);
    EXPECT_EQ(m.cohesion, 1e4);
    EXPECT_EQ(m.tensile_strength, 5e3);
    EXPECT_EQ(m.compressive_strength, 2e7);
    EXPECT_EQ(m.crushing_softening, 1e-3);
  }
  EXPECT_EQ(a.blocks[a.block_index("abutment_right")].support_kx, 1e8);
  EXPECT_EQ(a.blocks[a.block_index("abutment_right")].support_kr, 1e7);
  EXPECT_EQ(a.blocks[a.block_index("abutment_left")].support_kx, 0);
  EXPECT_EQ(a.joint_gap.joint, "voussoir_9/voussoir_10");
  EXPECT_EQ(a.joint_gap.extrados(), 1e-3);
  EXPECT_EQ(a.blocks[a.block_index("voussoir_5")].beam_kr, 1e6);

  r = run_demcal("scene wall --support-ky 1e9 --beam-kr 2e6 -o " + wall);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Scene w = load_scene(wall);
  EXPECT_EQ(w.blocks[w.block_index("base")].support_ky, 1e9);
  EXPECT_EQ(w.blocks[w.block_index("beam")].beam_kr, 2e6);

  r = run_demcal("scene arch --friction-residual-deg 40 --slip-softening 1e-3 -o " + arch);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("friction_residual_deg: must be in [0, friction_deg = 30.5] degrees, got 40"), std::string::npos)
      << r.output;
  r = run_demcal("scene arch --gap-extrados 1e-3 -o " + arch);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--gap-joint"), std::string::npos) << r.output;
  std::filesystem::remove_all(dir);
}

}  // namespace

// Each effect's finding reads its own fitted values (its names, not the base's), and an effect
// whose fit lacks a value it needs is named as itself rather than described wrongly.
TEST(EffectRegistry, EveryEffectDescribesItsFitInWords) {
  for (const Effect& effect : effect_registry()) {
    FittedEffect fit;
    fit.base_params = {{"kn", 1e9}, {"friction_deg", 35}};
    fit.params = fit.base_params;
    for (const EffectParameter& p : effect.parameters) fit.params["arch_joints." + p.name] = p.default_value;
    fit.target = "voussoir_9/voussoir_10";
    const std::string sentence = describe_fit(effect, fit);
    EXPECT_NE(sentence.rfind("effect ", 0), 0u) << effect.name << ": " << sentence;
    EXPECT_NE(sentence.find_first_of("0123456789"), std::string::npos) << effect.name << ": " << sentence;
    ASSERT_FALSE(effect.parameters.empty());
    EXPECT_EQ(fit.effect_value(effect.parameters.front().name), effect.parameters.front().default_value);
    fit.base_params["arch_joints." + effect.parameters.front().name] = 0;  // now a base parameter
    EXPECT_FALSE(fit.effect_value(effect.parameters.front().name)) << effect.name;
  }
  const Effect& softening = find_effect("friction-softening");
  FittedEffect bare;
  EXPECT_EQ(describe_fit(softening, bare), "effect friction-softening");
  bare.params = {{"friction_deg", 35}, {"friction_loss_deg", 10}, {"slip_softening", 0.002}};
  bare.base_params = {{"friction_deg", 35}};
  EXPECT_EQ(describe_fit(softening, bare),
            "friction is lost with sliding: its angle falls by about 10° (from 35° to 25°) over 2 mm of slip");
}
