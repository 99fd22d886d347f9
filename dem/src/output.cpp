#include "demcal/dem/simulation.hpp"

#include <nlohmann/json.hpp>

#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace demcal::dem {

using nlohmann::json;

json summary_json(const Recording& r) {
  json joints = json::array();
  for (const JointReport& j : r.joints)
    joints.push_back({{"name", j.name}, {"joint_group", j.joint_group}, {"open_fraction", j.open_fraction},
                      {"rotation", j.rotation}, {"slip", j.slip}, {"hinge", j.hinge}, {"sliding", j.sliding},
                      {"max_normal_stress", j.max_normal_stress}});
  return {{"status", to_string(r.status)},
          {"message", r.message},
          {"peak_force", r.peak_force},
          {"steps", r.steps},
          {"gravity_steps", r.gravity_steps},
          {"time_step", r.time_step},
          {"wall_time_s", r.wall_time_s},
          {"max_block_displacement", r.max_block_displacement},
          {"max_normal_stress", r.max_normal_stress},
          {"start_normal_stress", r.start_normal_stress},
          {"contact_point_updates", r.contact_point_updates},
          {"rows", r.time.size()},
          {"hinges", r.hinges},
          {"sliding_joints", r.sliding_joints},
          {"joints", joints}};
}

void write_curves_csv(const Recording& r, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << "time,force";
  for (const auto& g : r.gauge_names) out << "," << g;
  out << "\n" << std::setprecision(17);
  for (std::size_t i = 0; i < r.time.size(); ++i) {
    out << r.time[i] << "," << r.force[i];
    for (const auto& series : r.gauge_values) out << "," << series[i];
    out << "\n";
  }
  if (!out) throw std::runtime_error(path + ": writing failed");
}

void write_vtk(const Recording& r, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  std::size_t points = 0, ring_size = 0;
  for (const auto& b : r.final_blocks) {
    points += b.vertices.size();
    ring_size += b.vertices.size() + 1;
  }
  out << "# vtk DataFile Version 3.0\ndemcal final block positions\nASCII\nDATASET POLYDATA\n";
  out << "POINTS " << points << " double\n" << std::setprecision(12);
  for (const auto& b : r.final_blocks)
    for (const Vec2& v : b.vertices) out << v.x() << " " << v.y() << " 0\n";
  out << "POLYGONS " << r.final_blocks.size() << " " << ring_size << "\n";
  std::size_t next = 0;
  for (const auto& b : r.final_blocks) {
    out << b.vertices.size();
    for (std::size_t i = 0; i < b.vertices.size(); ++i) out << " " << next++;
    out << "\n";
  }
  out << "CELL_DATA " << r.final_blocks.size() << "\n";
  out << "SCALARS displacement double 1\nLOOKUP_TABLE default\n";
  for (const auto& b : r.final_blocks) out << b.displacement.norm() << "\n";
  out << "SCALARS rotation double 1\nLOOKUP_TABLE default\n";
  for (const auto& b : r.final_blocks) out << b.rotation << "\n";
  out << "SCALARS fixed int 1\nLOOKUP_TABLE default\n";
  for (const auto& b : r.final_blocks) out << (b.fixed ? 1 : 0) << "\n";
  out << "VECTORS displacement_vector double\n";
  for (const auto& b : r.final_blocks) out << b.displacement.x() << " " << b.displacement.y() << " 0\n";
  if (!out) throw std::runtime_error(path + ": writing failed");
}

}  // namespace demcal::dem
