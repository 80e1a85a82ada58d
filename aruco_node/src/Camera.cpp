#include <cpm/aruco/Camera.hpp>

#include <cpm/read_text_file.hpp>

#include <cpm/Error.hpp>

#include <opencv2/core/persistence.hpp>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <vector>

namespace cpm::aruco {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw Error(path + ": " + what); }

double number(const YAML::Node& root, const std::string& path, const char* name)
{
    const YAML::Node n = root[name];
    if (!n) fail(path, std::string("missing field ") + name);
    double v = 0;
    if (!n.IsScalar() || !YAML::convert<double>::decode(n, v)) fail(path, std::string(name) + ": expected a number");
    if (!std::isfinite(v)) fail(path, std::string(name) + ": expected a finite number");
    return v;
}

/// An opencv-matrix (rows, cols, dt, data) of rows × cols values (or cols × rows).
std::vector<double> matrix(const YAML::Node& root, const std::string& path, const char* name, int rows, int cols)
{
    const YAML::Node n = root[name];
    if (!n) fail(path, std::string("missing field ") + name);
    if (!n.IsMap() || !n["rows"] || !n["cols"] || !n["data"] || !n["rows"].IsScalar() || !n["cols"].IsScalar() || !n["data"].IsSequence())
        fail(path, std::string(name) + ": expected an opencv-matrix (rows, cols, dt, data)");
    long long r = 0, c = 0;
    if (!YAML::convert<long long>::decode(n["rows"], r) || !YAML::convert<long long>::decode(n["cols"], c))
        fail(path, std::string(name) + ": expected an opencv-matrix (rows, cols, dt, data)");
    if (r * c != rows * cols || r <= 0 || c <= 0) {
        fail(path, std::string(name) + ": expected " + std::to_string(rows) + "×" + std::to_string(cols) + " values, got " +
                       std::to_string(r) + "×" + std::to_string(c));
    }
    const YAML::Node data = n["data"];
    if (data.size() != size_t(rows * cols)) {
        fail(path, std::string(name) + ": data holds " + std::to_string(data.size()) + " values, rows × cols is " +
                       std::to_string(rows * cols));
    }
    std::vector<double> out;
    for (size_t i = 0; i < data.size(); ++i) {
        double v = 0;
        if (!data[i].IsScalar() || !YAML::convert<double>::decode(data[i], v)) fail(path, std::string(name) + ": value " + std::to_string(i) + " is not a number");
        if (!std::isfinite(v)) fail(path, std::string(name) + ": value " + std::to_string(i) + " is not finite");
        out.push_back(v);
    }
    return out;
}

}  // namespace

Camera Camera::load(const std::string& path)
{
    std::string text = read_text_file(path, "camera file");  // names a directory or a missing file
    // Read with yaml-cpp, not OpenCV's FileStorage: OpenCV 4.6's reader loops forever on some
    // malformed files (found by fuzzing). OpenCV writes a first line "%YAML:1.0", which is not
    // standard YAML: it is dropped.
    if (text.rfind("%YAML", 0) == 0) text.erase(0, text.find('\n') == std::string::npos ? text.size() : text.find('\n'));
    YAML::Node root;
    try {
        root = YAML::Load(text);
    } catch (const YAML::Exception& e) {
        fail(path, "not an OpenCV FileStorage YAML file (line " + std::to_string(e.mark.line + 2) + ": " + e.msg + ")");
    }
    if (!root.IsMap()) fail(path, "not an OpenCV FileStorage YAML file (expected a map of fields: image_width, image_height, camera_matrix, ...)");
    Camera c;
    double w = number(root, path, "image_width"), h = number(root, path, "image_height");
    if (w < 16 || h < 16 || w > 8192 || h > 8192 || w != std::floor(w) || h != std::floor(h)) {
        fail(path, "image_width and image_height must be whole numbers of pixels, 16..8192");
    }
    c.width = int(w);
    c.height = int(h);
    const auto k = matrix(root, path, "camera_matrix", 3, 3);
    c.camera_matrix = cv::Matx33d(k.data());
    if (c.fx() <= 0 || c.fy() <= 0) fail(path, "camera_matrix: the focal lengths fx, fy must be > 0");
    const auto d = matrix(root, path, "distortion_coefficients", 1, 5);
    for (int i = 0; i < 5; ++i) c.distortion[i] = d[size_t(i)];
    c.mount.x = number(root, path, "mount_x");
    c.mount.y = number(root, path, "mount_y");
    c.mount.z = number(root, path, "mount_z");
    c.mount.yaw = number(root, path, "mount_yaw");
    c.mount.pitch = number(root, path, "mount_pitch");
    if (std::abs(c.mount.pitch) >= M_PI / 2) fail(path, "mount_pitch: must be within ±90°");
    return c;
}

void Camera::save(const std::string& path) const
{
    cv::FileStorage fs(path, cv::FileStorage::WRITE | cv::FileStorage::FORMAT_YAML);
    if (!fs.isOpened()) throw Error(path + ": cannot write the camera file");
    fs << "image_width" << width << "image_height" << height;
    fs << "camera_matrix" << cv::Mat(camera_matrix);
    fs << "distortion_coefficients" << cv::Mat(distortion).reshape(1, 1);
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
