#include <cpm/aruco/Camera.hpp>

#include <cpm/read_text_file.hpp>

#include <cpm/Error.hpp>
#include <cpm/checkers/YamlChecker.hpp>

#include <opencv2/core/persistence.hpp>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <vector>

namespace cpm::aruco {
namespace {

using Checker = checkers::YamlChecker;

/// The field `name`, a finite number; 0 with an error said when it is not.
double number(Checker& c, const YAML::Node& root, const char* name)
{
    const YAML::Node n = root[name];
    if (!n) {
        c.error("", std::string("missing field ") + name);
        return 0;
    }
    return c.number(n, name).value_or(0);
}

/// An opencv-matrix (rows, cols, dt, data) of rows × cols values (or cols × rows); empty with an
/// error said when it is not.
std::vector<double> matrix(Checker& c, const YAML::Node& root, const char* name, int rows, int cols)
{
    const YAML::Node n = root[name];
    if (!n) {
        c.error("", std::string("missing field ") + name);
        return {};
    }
    long long r = 0, k = 0;
    if (!n.IsMap() || !n["rows"] || !n["cols"] || !n["data"] || !n["data"].IsSequence() || !n["rows"].IsScalar() ||
        !n["cols"].IsScalar() || !YAML::convert<long long>::decode(n["rows"], r) || !YAML::convert<long long>::decode(n["cols"], k)) {
        c.error(n, name, "expected an opencv-matrix (rows, cols, dt, data)");
        return {};
    }
    if (r * k != rows * cols || r <= 0 || k <= 0) {
        c.error(n, name, "expected " + std::to_string(rows) + "×" + std::to_string(cols) + " values, got " + std::to_string(r) + "×" + std::to_string(k));
        return {};
    }
    const YAML::Node data = n["data"];
    if (data.size() != size_t(rows * cols)) {
        c.error(data, name, "data holds " + std::to_string(data.size()) + " values, rows × cols is " + std::to_string(rows * cols));
        return {};
    }
    std::vector<double> out;
    for (size_t i = 0; i < data.size(); ++i) {
        const auto v = c.number(data[i], std::string(name) + ".data[" + std::to_string(i) + "]");
        if (!v) return {};
        out.push_back(*v);
    }
    return out;
}

/// The file's text as yaml-cpp reads it, or an error said.
YAML::Node parse(Checker& c, std::string text)
{
    // Read with yaml-cpp, not OpenCV's FileStorage: OpenCV 4.6's reader loops forever on some
    // malformed files (found by fuzzing). OpenCV writes a first line "%YAML:1.0", which is not
    // standard YAML: it is dropped.
    if (text.rfind("%YAML", 0) == 0) text.erase(0, text.find('\n') == std::string::npos ? text.size() : text.find('\n'));
    try {
        YAML::Node root = YAML::Load(text);
        if (root.IsMap()) return root;
        c.error("", "not an OpenCV FileStorage YAML file (expected a map of fields: image_width, image_height, camera_matrix, ...)");
    } catch (const YAML::Exception& e) {
        c.error("", "not an OpenCV FileStorage YAML file (line " + std::to_string(e.mark.line + 2) + ": " + e.msg + ")");
    }
    return {};
}

/// world_x, world_y, world_z and world_rotation (a rotation matrix), all or none; nullopt when
/// none is there (and the placement does not ask for them).
std::optional<OverheadPose> overhead_pose(Checker& check, const YAML::Node& root, CameraPlacement placement)
{
    const bool any = root["world_x"] || root["world_y"] || root["world_z"] || root["world_rotation"];
    if (!any) {
        if (placement == CameraPlacement::overhead) {
            check.error("", "no overhead pose (world_x, world_y, world_z, world_rotation): this camera has not been located in "
                            "the map; run cpm camera locate --camera FILE --world FILE --image IMAGE");
        }
        return std::nullopt;
    }
    OverheadPose pose;
    pose.position = {number(check, root, "world_x"), number(check, root, "world_y"), number(check, root, "world_z")};
    const auto r = matrix(check, root, "world_rotation", 3, 3);
    if (r.empty()) return std::nullopt;
    pose.rotation = cv::Matx33d(r.data());
    const double off = cv::norm(cv::Mat(pose.rotation.t() * pose.rotation - cv::Matx33d::eye()), cv::NORM_INF);
    if (off > 1e-3 || cv::determinant(pose.rotation) < 0) {
        check.error(root["world_rotation"], "world_rotation", "not a rotation matrix (R^T R differs from I by " + std::to_string(off) +
                                                                   ", det " + std::to_string(cv::determinant(pose.rotation)) + ")");
        return std::nullopt;
    }
    if (root["world_residual_px"]) pose.residual_px = number(check, root, "world_residual_px");
    return pose;
}

}  // namespace

Camera Camera::load(const std::string& path, CameraPlacement placement)
{
    Checker check(path);
    const YAML::Node root = parse(check, read_text_file(path, "camera file"));  // names a directory or a missing file
    check.throw_if_errors();
    Camera c;
    const double w = number(check, root, "image_width"), h = number(check, root, "image_height");
    if (check.ok() && (w < 16 || h < 16 || w > 8192 || h > 8192 || w != std::floor(w) || h != std::floor(h))) {
        check.error("", "image_width and image_height must be whole numbers of pixels, 16..8192");
    }
    c.width = int(w);
    c.height = int(h);
    if (const auto k = matrix(check, root, "camera_matrix", 3, 3); !k.empty()) {
        c.camera_matrix = cv::Matx33d(k.data());
        if (c.fx() <= 0 || c.fy() <= 0) check.error(root["camera_matrix"], "camera_matrix", "the focal lengths fx, fy must be > 0");
    }
    const auto d = matrix(check, root, "distortion_coefficients", 1, 5);
    for (size_t i = 0; i < d.size(); ++i) c.distortion[int(i)] = d[i];
    if (placement == CameraPlacement::on_car || root["mount_x"]) {
        c.mount.x = number(check, root, "mount_x");
        c.mount.y = number(check, root, "mount_y");
        c.mount.z = number(check, root, "mount_z");
        c.mount.yaw = number(check, root, "mount_yaw");
        c.mount.pitch = number(check, root, "mount_pitch");
        if (std::abs(c.mount.pitch) >= M_PI / 2) check.error(root["mount_pitch"], "mount_pitch", "must be within ±90°");
    }
    c.overhead = overhead_pose(check, root, placement);
    check.throw_if_errors();
    return c;
}

void Camera::save(const std::string& path) const
{
    cv::FileStorage fs(path, cv::FileStorage::WRITE | cv::FileStorage::FORMAT_YAML);
    if (!fs.isOpened()) throw Error(path + ": cannot write the camera file");
    fs << "image_width" << width << "image_height" << height;
    fs << "camera_matrix" << cv::Mat(camera_matrix);
    fs << "distortion_coefficients" << cv::Mat(distortion).reshape(1, 1);
    if (overhead) {
        fs << "world_x" << overhead->position[0] << "world_y" << overhead->position[1] << "world_z" << overhead->position[2];
        fs << "world_rotation" << cv::Mat(overhead->rotation);
        if (overhead->residual_px >= 0) fs << "world_residual_px" << overhead->residual_px;
        return;
    }
    fs << "mount_x" << mount.x << "mount_y" << mount.y << "mount_z" << mount.z << "mount_yaw" << mount.yaw << "mount_pitch"
       << mount.pitch;
}

Camera Camera::ideal(int width, int height, double horizontal_fov, CameraMount mount)
{
    Camera c;
    c.width = width;
    c.height = height;
    const double f = (width / 2.0) / std::tan(horizontal_fov / 2);
    c.camera_matrix = cv::Matx33d(f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1);
    c.mount = mount;
    return c;
}

std::string Camera::size_mismatch(int image_width, int image_height) const
{
    if (image_width == width && image_height == height) return "";
    return std::to_string(image_width) + "×" + std::to_string(image_height) + " px, the camera file says " + std::to_string(width) +
           "×" + std::to_string(height);
}

cv::Matx33d Camera::car_from_camera_rotation() const
{
    // A camera looking along the car's x axis: its x (right) is the car's -y, its y (down) the
    // car's -z, its z (ahead) the car's x. Then pitch about the car's y (down is +), then yaw.
    const cv::Matx33d base(0, 0, 1, -1, 0, 0, 0, -1, 0);
    const double cp = std::cos(mount.pitch), sp = std::sin(mount.pitch);
    const double cy = std::cos(mount.yaw), sy = std::sin(mount.yaw);
    const cv::Matx33d pitch(cp, 0, sp, 0, 1, 0, -sp, 0, cp);
    const cv::Matx33d yaw(cy, -sy, 0, sy, cy, 0, 0, 0, 1);
    return yaw * pitch * base;
}

cv::Vec3d Camera::to_car(const cv::Vec3d& p_camera) const
{
    return car_from_camera_rotation() * p_camera + cv::Vec3d(mount.x, mount.y, mount.z);
}

cv::Vec3d Camera::to_camera(const cv::Vec3d& p_car) const
{
    return car_from_camera_rotation().t() * (p_car - cv::Vec3d(mount.x, mount.y, mount.z));
}

}  // namespace cpm::aruco
