!> Slice rectangles (thesis section 3.3): a plane through the model, a rectangle on it and its
!> pixel grid.
!>
!> A slice has an origin o (mm, world frame), two orthonormal in-plane axes u and v and the pixel
!> size R_s (mm per pixel). Pixel (i, j), i = 1..nu along u and j = 1..nv along v, is the square
!> whose centre is o + (i - 1/2) R_s u + (j - 1/2) R_s v; a pixel is labelled by what contains its
!> centre. The normal is n = u x v.
!>
!> Usage:
!>     call new_axis_plane(plane, 3, 10.0_wp, [20.0_wp, 20.0_wp], 0.05_wp, error)   ! z = 10 mm
!>     call new_slice_plane(plane, origin, u, v, [20.0_wp, 20.0_wp], 0.05_wp, error)
!>     x = pixel_center(plane, i, j)
module anm_slicing_plane
   use anm_core_kinds, only: wp
   use anm_core_vector, only: cross
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   implicit none
   private

   public :: slice_plane_type, new_slice_plane, new_axis_plane, pixel_center, axis_tolerance

   !> Largest accepted |u.v| and ||u| - 1|, ||v| - 1| of given in-plane axes (they are then
   !> re-orthonormalised exactly).
   real(wp), parameter :: axis_tolerance = 1.0e-6_wp

   !> A slice rectangle and its pixel grid.
   type :: slice_plane_type
      !> Corner of the rectangle (mm, world frame).
      real(wp) :: origin(3) = 0.0_wp
      !> In-plane unit axes and the unit normal u x v.
      real(wp) :: u(3) = [1.0_wp, 0.0_wp, 0.0_wp], v(3) = [0.0_wp, 1.0_wp, 0.0_wp], normal(3) = [0.0_wp, 0.0_wp, 1.0_wp]
      !> Pixel size R_s (mm per pixel).
      real(wp) :: pixel = 1.0_wp
      !> Pixels along u and along v.
      integer :: nu = 1, nv = 1
   end type slice_plane_type

contains

   !> A slice rectangle from its corner, in-plane axes, size (mm) and pixel size. The number of
   !> pixels along each axis is nint(size / pixel), at least 1.
   pure subroutine new_slice_plane(plane, origin, u, v, size, pixel, error)
      !> Slice to build.
      type(slice_plane_type), intent(out) :: plane
      !> Corner of the rectangle (mm).
      real(wp), intent(in) :: origin(3)
      !> In-plane axes (unit length and orthogonal to within axis_tolerance).
      real(wp), intent(in) :: u(3), v(3)
      !> Width along u and height along v (mm, > 0).
      real(wp), intent(in) :: size(2)
      !> Pixel size R_s (mm per pixel, > 0).
      real(wp), intent(in) :: pixel
      !> Error naming the offending argument.
      type(error_type), allocatable, intent(out) :: error
      real(wp) :: vv(3)

      if (.not. (pixel > 0.0_wp .and. pixel < huge(1.0_wp))) then
         call fatal_error(error, "slice: pixel size must be positive, got "//to_string(pixel), error_code%value)
         return
      end if
      if (.not. (all(size > 0.0_wp) .and. all(size < huge(1.0_wp)))) then
         call fatal_error(error, "slice: size must be positive, got "//to_string(size(1))//" x "// &
                          to_string(size(2)), error_code%value)
         return
      end if
      if (any(size / pixel > 1.0e6_wp)) then
         call fatal_error(error, "slice: more than 10^6 pixels along one axis (size / pixel size)", error_code%value)
         return
      end if
      if (abs(norm2(u) - 1.0_wp) > axis_tolerance .or. abs(norm2(v) - 1.0_wp) > axis_tolerance .or. &
          abs(dot_product(u, v)) > axis_tolerance) then
         call fatal_error(error, "slice: in-plane axes u and v must be orthonormal, got |u| = "//to_string(norm2(u))// &
                          ", |v| = "//to_string(norm2(v))//", u.v = "//to_string(dot_product(u, v)), error_code%value)
         return
      end if
      if (any(origin /= origin)) then
         call fatal_error(error, "slice: origin is not a number", error_code%value)
         return
      end if
      plane%origin = origin
      plane%u = u / norm2(u)
      vv = v - dot_product(v, plane%u) * plane%u
      plane%v = vv / norm2(vv)
      plane%normal = cross(plane%u, plane%v)
      plane%pixel = pixel
      plane%nu = max(1, nint(size(1) / pixel))
      plane%nv = max(1, nint(size(2) / pixel))
   end subroutine new_slice_plane

   !> The slice x_axis = position covering [0, size(1)] x [0, size(2)] of the other two axes in
   !> increasing order (axis 1: u = y, v = z; axis 2: u = x, v = z; axis 3: u = x, v = y).
   pure subroutine new_axis_plane(plane, axis, position, size, pixel, error)
      !> Slice to build.
      type(slice_plane_type), intent(out) :: plane
      !> Normal axis: 1 (x), 2 (y) or 3 (z).
      integer, intent(in) :: axis
      !> Position along the normal axis (mm).
      real(wp), intent(in) :: position
      !> Extent along the two in-plane axes (mm), usually the box edges.
      real(wp), intent(in) :: size(2)
      !> Pixel size R_s (mm per pixel).
      real(wp), intent(in) :: pixel
      !> Error naming the offending argument.
      type(error_type), allocatable, intent(out) :: error
      real(wp) :: eye(3, 3), origin(3)
      integer :: iu, iv

      if (axis < 1 .or. axis > 3) then
         call fatal_error(error, "slice: axis must be 1, 2 or 3 (x, y, z), got "//to_string(axis), error_code%value)
         return
      end if
      eye = 0.0_wp
      eye(1, 1) = 1.0_wp
      eye(2, 2) = 1.0_wp
      eye(3, 3) = 1.0_wp
      iu = merge(2, 1, axis == 1)
      iv = merge(2, 3, axis == 3)
      origin = 0.0_wp
      origin(axis) = position
      call new_slice_plane(plane, origin, eye(:, iu), eye(:, iv), size, pixel, error)
   end subroutine new_axis_plane

   !> World position (mm) of the centre of pixel (i, j).
   pure function pixel_center(plane, i, j) result(x)
      !> Slice.
      type(slice_plane_type), intent(in) :: plane
      !> Pixel indices, 1..nu and 1..nv.
      integer, intent(in) :: i, j
      real(wp) :: x(3)
      x = plane%origin + ((i - 0.5_wp) * plane%pixel) * plane%u + ((j - 0.5_wp) * plane%pixel) * plane%v
   end function pixel_center

end module anm_slicing_plane
