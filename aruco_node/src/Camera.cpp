#include <cpm/aruco/Camera.hpp>

#include <cpm/Error.hpp>

#include <opencv2/core/persistence.hpp>

#include <cmath>
#include <fstream>

namespace cpm::aruco {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw Error(path + ": " + what); }

double number(const cv::FileStorage& fs, const std::string& path, const char* name)
{
    cv::FileNode n = fs[name];
    if (n.empty()) fail(path, std::string("missing field ") + name);
    if (!n.isReal() && !n.isInt()) fail(path, std::string(name) + ": expected a number");
    double v = double(n);
    if (!std::isfinite(v)) fail(path, std::string(name) + ": expected a finite number");
    return v;
}

cv::Mat matrix(const cv::FileStorage& fs, const std::string& path, const char* name, int rows, int cols)
{
    cv::FileNode n = fs[name];
    if (n.empty()) fail(path, std::string("missing field ") + name);
    // The size first: a file may claim any rows and cols, and OpenCV would allocate them.
    const cv::FileNode r = n.isMap() ? n["rows"] : cv::FileNode(), c = n.isMap() ? n["cols"] : cv::FileNode();
    if (r.empty() || c.empty() || !r.isInt() || !c.isInt()) fail(path, std::string(name) + ": expected an opencv-matrix");
    if (int(r) != rows || int(c) != cols) {
        if (int64_t(int(r)) * int(c) != int64_t(rows) * cols)
            fail(path, std::string(name) + ": expected " + std::to_string(rows) + "×" + std::to_string(cols) + " values, got " +
                           std::to_string(int(r)) + "×" + std::to_string(int(c)));
    }
    cv::Mat m;
    try {
        n >> m;
    } catch (const std::exception&) {
        fail(path, std::string(name) + ": expected an opencv-matrix");
    }
    if (m.empty() || int(m.total()) != rows * cols) {
        fail(path, std::string(name) + ": expected " + std::to_string(rows) + "×" + std::to_string(cols) + " values, got " +
                       std::to_string(m.rows) + "×" + std::to_string(m.cols));
    }
    m.convertTo(m, CV_64F);
    for (int i = 0; i < int(m.total()); ++i) {
        if (!std::isfinite(m.at<double>(i))) fail(path, std::string(name) + ": value " + std::to_string(i) + " is not finite");
    }
    return m.reshape(1, rows);
}

}  // namespace

Camera Camera::load(const std::string& path)
{
    {
        std::ifstream probe(path);
        if (!probe) fail(path, "cannot read the camera file");
    }
    cv::FileStorage fs;
    try {
        if (!fs.open(path, cv::FileStorage::READ)) fail(path, "not an OpenCV FileStorage YAML file");
    } catch (const cv::Exception& e) {
        fail(path, "not an OpenCV FileStorage YAML file (" + std::string(e.err) + ")");
    } catch (const std::exception& e) {  // OpenCV's parser also lets std::length_error and the like out
        fail(path, "not an OpenCV FileStorage YAML file (" + std::string(e.what()) + ")");
    }
    if (!fs.root().isMap()) fail(path, "expected a map of fields (image_width, image_height, camera_matrix, ...)");
    Camera c;
    double w = number(fs, path, "image_width"), h = number(fs, path, "image_height");
    if (w < 16 || h < 16 || w > 8192 || h > 8192 || w != std::floor(w) || h != std::floor(h)) {
        fail(path, "image_width and image_height must be whole numbers of pixels, 16..8192");
    }
    c.width = int(w);
    c.height = int(h);
    cv::Mat k = matrix(fs, path, "camera_matrix", 3, 3);
    c.camera_matrix = cv::Matx33d(k.ptr<double>());
    if (c.fx() <= 0 || c.fy() <= 0) fail(path, "camera_matrix: the focal lengths fx, fy must be > 0");
    cv::Mat d = matrix(fs, path, "distortion_coefficients", 1, 5);
    for (int i = 0; i < 5; ++i) c.distortion[i] = d.at<double>(i);
    c.mount.x = number(fs, path, "mount_x");
    c.mount.y = number(fs, path, "mount_y");
    c.mount.z = number(fs, path, "mount_z");
    c.mount.yaw = number(fs, path, "mount_yaw");
    c.mount.pitch = number(fs, path, "mount_pitch");
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
