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

/// The marker lying flat on a car's roof, for the overhead camera (IPS): centred over the point
/// whose pose vehicleObservation reports, its x axis along the car's heading; `size` is the side
/// of its black square, `z` the roof's height above the floor, metres.
struct RoofMarker
{
    int vehicle_id = 0;
    int id = 0;
    double size = 0.08, z = 0.1;
};

/// A marker lying flat on the floor at a known place, for locating the overhead camera: its
/// centre (x, y), the direction of its x axis in the map (yaw, radians), the side of its black
/// square (size, metres).
struct FloorMarker
{
    int id = 0;
    double x = 0, y = 0, yaw = 0, size = 0.15;
};

/// The 2-D world the simulated cars drive in: walls, markers and gates (format: scenarios/README.md).
class World
{
public:
    World() = default;
    World(std::vector<Segment> walls, std::vector<Marker> markers, std::vector<Gate> gates = {});

    /// Roof and floor markers (the overhead camera's) are set on their own.
    void set_overhead_markers(std::vector<RoofMarker> roof, std::vector<FloorMarker> floor);

    /// Reads a map file `{"walls": [[x1, y1, x2, y2], ...], "markers": [...], "gates": [...],
    /// "roof_markers": {"<vehicle id>": {"id", "size", "z"}}, "floor_markers": [...]}`.
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
    /// The cars' roof markers, by vehicle id order.
    const std::vector<RoofMarker>& roof_markers() const { return roof_markers_; }
    const std::vector<FloorMarker>& floor_markers() const { return floor_markers_; }
    /// The roof marker with this marker id, or nullptr.
    const RoofMarker* roof_marker(int marker_id) const;
    /// The roof marker car `vehicle_id` wears, or nullptr.
    const RoofMarker* roof_marker_of(int vehicle_id) const;

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
    std::vector<RoofMarker> roof_markers_;
    std::vector<FloorMarker> floor_markers_;
};

/// Distance along the ray from (x, y) in direction (dx, dy) (unit vector) to the segment,
/// or a negative value when it misses.
double ray_segment_distance(double x, double y, double dx, double dy, const Segment& s);

/// Metres from (x, y) to the nearest point of the segment.
double point_segment_distance(double x, double y, const Segment& s);

/// True when the two segments cross or touch.
bool segments_intersect(const Segment& a, const Segment& b);

}  // namespace cpm::vehicle
