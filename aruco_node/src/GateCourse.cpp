#include <cpm/aruco/GateCourse.hpp>

#include <cmath>
#include <cstdio>
#include <random>

namespace cpm::aruco {

vehicle::World gate_course(uint32_t seed, const GateCourseOptions& o)
{
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    const double half = o.corridor_width / 2;
    const double end = o.first_gate + o.spacing * (o.gates - 1) + 3.0;
    std::vector<vehicle::Segment> walls{{-1.5, -half, end, -half}, {-1.5, half, end, half}, {-1.5, -half, -1.5, half}, {end, -half, end, half}};
    std::vector<vehicle::Marker> markers;
    std::vector<vehicle::Gate> gates;
    for (int k = 0; k < o.gates; ++k) {
        const double cx = o.first_gate + k * o.spacing, cy = o.max_offset * unit(rng);
        const double a = o.max_angle * unit(rng);  // the direction of travel through the gate
        const double lx = -std::sin(a), ly = std::cos(a);
        const double w = o.gate_width / 2;
        // Both markers face the approaching car: against the direction of travel.
        markers.push_back({2 * k, cx + w * lx, cy + w * ly, a + M_PI, o.marker_size, o.marker_z});
        markers.push_back({2 * k + 1, cx - w * lx, cy - w * ly, a + M_PI, o.marker_size, o.marker_z});
        gates.push_back({2 * k, 2 * k + 1});
    }
    return vehicle::World(std::move(walls), std::move(markers), std::move(gates));
}

std::vector<GatePassage> gate_passages(const vehicle::World& world, const std::vector<PathPoint>& path, double car_width)
{
    std::vector<GatePassage> out;
    for (size_t g = 0; g < world.gates().size(); ++g) {
        GatePassage passage;
        passage.gate = int(g);
        const vehicle::Marker* left = world.marker(world.gates()[g].left);
        const vehicle::Marker* right = world.marker(world.gates()[g].right);
        if (!left || !right) {
            out.push_back(passage);
            continue;
        }
        const double cx = (left->x + right->x) / 2, cy = (left->y + right->y) / 2;
        const double half = std::hypot(left->x - right->x, left->y - right->y) / 2;
        const double ux = (left->x - right->x) / (2 * half), uy = (left->y - right->y) / (2 * half);  // towards the left marker
        const double tx = uy, ty = -ux;  // the direction of travel (left is to its left)
        for (size_t i = 1; i < path.size() && !passage.passed; ++i) {
            const auto& p0 = path[i - 1].pose;
            const auto& p1 = path[i].pose;
            const double s0 = (p0.x - cx) * tx + (p0.y - cy) * ty, s1 = (p1.x - cx) * tx + (p1.y - cy) * ty;
            if (!(s0 < 0 && s1 >= 0)) continue;
            const double f = s0 / (s0 - s1);
            const double x = p0.x + f * (p1.x - p0.x), y = p0.y + f * (p1.y - p0.y);
            const double offset = (x - cx) * ux + (y - cy) * uy;
            if (std::abs(offset) > half) continue;  // crossed the gate's line outside the gate
            passage.passed = true;
            passage.t = path[i - 1].t + f * (path[i].t - path[i - 1].t);
            passage.offset = offset;
            const double inner = half - std::max(left->size, right->size) / 2;  // marker inner edge from the centre
            passage.clearance = inner - std::abs(offset) - car_width / 2;
        }
        out.push_back(passage);
    }
    return out;
}

bool all_gates_passed(const std::vector<GatePassage>& passages, double min_clearance, std::string* why)
{
    double last_t = -1e300;
    for (const auto& p : passages) {
        char text[160] = "";
        if (!p.passed) {
            std::snprintf(text, sizeof text, "gate %d was not passed", p.gate + 1);
        } else if (p.t < last_t) {
            std::snprintf(text, sizeof text, "gate %d was passed out of order", p.gate + 1);
        } else if (p.clearance < min_clearance) {
            std::snprintf(text, sizeof text, "gate %d passed %.3f m from its centre: %.3f m from a marker (need %.3f)", p.gate + 1,
                          p.offset, p.clearance, min_clearance);
        }
        if (text[0]) {
            if (why) *why = text;
            return false;
        }
        last_t = p.t;
    }
    return true;
}

}  // namespace cpm::aruco
