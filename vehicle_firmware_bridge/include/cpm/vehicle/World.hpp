#pragma once
#include <string>
#include <vector>

namespace cpm::vehicle {

/// A wall: the segment from (x1, y1) to (x2, y2), metres.
struct Segment
{
    double x1 = 0, y1 = 0, x2 = 0, y2 = 0;
};

/// An ArUco marker standing upright, facing along yaw (radians: the direction its printed
/// side looks); size is the side of its black square in metres, z the height of its centre.
struct Marker
{
    int id = 0;
    double x = 0, y = 0, yaw = 0, size = 0.1, z = 0.1;
};

/// Two markers side by side, facing the car that drives between them; `left` is on the
/// driver's left when passing through.
struct Gate
{
    int left = 0, right = 0;
};

/// The 2-D world the simulated cars drive in: walls, markers and gates (format: scenarios/README.md).
class World
{
public:
    World() = default;
    World(std::vector<Segment> walls, std::vector<Marker> markers, std::vector<Gate> gates = {});

    /// Reads a map file `{"walls": [[x1, y1, x2, y2], ...], "markers": [...], "gates": [...]}`.
    /// Throws cpm::Error naming the file and the JSON path of the first wrong entry.
    static World load(const std::string& path);
    /// The same from JSON text; `source` names it in error messages.
    static World parse(const std::string& json_text, const std::string& source);

    /// The map file's JSON text (what load() reads back).
    std::string to_json() const;

    const std::vector<Segment>& walls() const { return walls_; }
    const std::vector<Marker>& markers() const { return markers_; }
    const std::vector<Gate>& gates() const { return gates_; }
    /// The marker with this id, or nullptr.
    const Marker* marker(int id) const;

    /// Distance (m) from (x, y) along direction `angle` (rad) to the nearest wall or extra
    /// segment, or max_range when nothing is closer. O(walls + extra).
    double cast_ray(double x, double y, double angle, double max_range,
                    const std::vector<Segment>& extra = {}) const;
    /// The first wall that crosses or touches one of `outline`'s segments, if any. O(walls × outline).
    const Segment* wall_hit(const std::vector<Segment>& outline) const;

    /// Metres from (x, y) to the nearest wall; infinity in a world without walls.
    double nearest_wall(double x, double y) const;

private:
    std::vector<Segment> walls_;
    std::vector<Marker> markers_;
    std::vector<Gate> gates_;
};

/// Distance along the ray from (x, y) in direction (dx, dy) (unit vector) to the segment,
/// or a negative value when it misses.
double ray_segment_distance(double x, double y, double dx, double dy, const Segment& s);

/// Metres from (x, y) to the nearest point of the segment.
double point_segment_distance(double x, double y, const Segment& s);

/// True when the two segments cross or touch.
bool segments_intersect(const Segment& a, const Segment& b);

}  // namespace cpm::vehicle
