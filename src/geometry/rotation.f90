!> Poses: uniformly random rotations (Haar measure on SO(3)), body <-> world transforms and
!> scaling a shape to a target width.
!>
!> Uniform rotations come from uniform unit quaternions (Shoemake 1992): with u1, u2, u3 uniform
!> on [0, 1), q = (sqrt(1-u1) sin 2 pi u2, sqrt(1-u1) cos 2 pi u2, sqrt(u1) sin 2 pi u3,
!> sqrt(u1) cos 2 pi u3). Uniform Euler angles are *not* uniform: they crowd the rotated axes
!> towards the poles (the tests show it).
!>
!> Convention (docs/conventions.md): R maps body to world, world = c + s R body; a world point x is inside
!> the particle iff y = R^T (x - c) / s satisfies |y| <= r(y/|y|).
!>
!> Usage:
!>     rot = random_rotation(rng)
!>     x = body_to_world(rot, center, scale, y)
!>     y = world_to_body(rot, center, scale, x)
module anm_geometry_rotation
   use anm_core_kinds, only: wp, two_pi
   use anm_core_random, only: rng_type
   implicit none
   private

   public :: random_rotation, quaternion_to_matrix, body_to_world, world_to_body, rotation_about_axis, &
      & scale_for_width, is_rotation

contains

   !> Rotation matrix of the unit quaternion (w, x, y, z).
   pure function quaternion_to_matrix(q) result(rot)
      !> Quaternion (w, x, y, z), normalised here.
      real(wp), intent(in) :: q(4)
      real(wp) :: rot(3, 3)
      real(wp) :: w, x, y, z, n
      n = norm2(q)
      w = q(1) / n
      x = q(2) / n
      y = q(3) / n
      z = q(4) / n
      rot(1, :) = [1.0_wp - 2.0_wp * (y * y + z * z), 2.0_wp * (x * y - w * z), 2.0_wp * (x * z + w * y)]
      rot(2, :) = [2.0_wp * (x * y + w * z), 1.0_wp - 2.0_wp * (x * x + z * z), 2.0_wp * (y * z - w * x)]
      rot(3, :) = [2.0_wp * (x * z - w * y), 2.0_wp * (y * z + w * x), 1.0_wp - 2.0_wp * (x * x + y * y)]
   end function quaternion_to_matrix

   !> A rotation drawn uniformly from SO(3) (Haar measure).
   function random_rotation(rng) result(rot)
      !> Random stream.
      type(rng_type), intent(inout) :: rng
      real(wp) :: rot(3, 3)
      real(wp) :: u1, u2, u3, a, b
      u1 = rng%uniform()
      u2 = rng%uniform()
      u3 = rng%uniform()
      a = sqrt(1.0_wp - u1)
      b = sqrt(u1)
      rot = quaternion_to_matrix([b * cos(two_pi * u3), a * sin(two_pi * u2), a * cos(two_pi * u2), &
                                  b * sin(two_pi * u3)])
   end function random_rotation

   !> Rotation by angle `angle` (radians) about the unit axis `axis` (Rodrigues).
   pure function rotation_about_axis(axis, angle) result(rot)
      !> Axis (normalised here).
      real(wp), intent(in) :: axis(3)
      !> Angle, right-handed.
      real(wp), intent(in) :: angle
      real(wp) :: rot(3, 3)
      real(wp) :: h, s
      h = 0.5_wp * angle
      s = sin(h) / norm2(axis)
      rot = quaternion_to_matrix([cos(h), s * axis(1), s * axis(2), s * axis(3)])
   end function rotation_about_axis

   !> World coordinates of body point y: c + s R y.
   pure function body_to_world(rot, center, scale, y) result(x)
      !> Body-to-world rotation.
      real(wp), intent(in) :: rot(3, 3)
      !> Centre (world, mm).
      real(wp), intent(in) :: center(3)
      !> mm per shape unit.
      real(wp), intent(in) :: scale
      !> Body point.
      real(wp), intent(in) :: y(3)
      real(wp) :: x(3)
      x = center + scale * matmul(rot, y)
   end function body_to_world

   !> Body coordinates of world point x: R^T (x - c) / s.
   pure function world_to_body(rot, center, scale, x) result(y)
      !> Body-to-world rotation.
      real(wp), intent(in) :: rot(3, 3)
      !> Centre (world, mm).
      real(wp), intent(in) :: center(3)
      !> mm per shape unit.
      real(wp), intent(in) :: scale
      !> World point.
      real(wp), intent(in) :: x(3)
      real(wp) :: y(3)
      y = matmul(x - center, rot) / scale
   end function world_to_body

   !> Scale (mm per shape unit) that gives a shape of width `shape_width` (shape units) the
   !> width `target_width` (mm).
   elemental function scale_for_width(shape_width, target_width) result(scale)
      !> Width of the shape in its own units.
      real(wp), intent(in) :: shape_width
      !> Wanted width, mm.
      real(wp), intent(in) :: target_width
      real(wp) :: scale
      scale = target_width / shape_width
   end function scale_for_width

   !> True when R is proper orthogonal to tolerance tol.
   pure function is_rotation(rot, tol) result(ok)
      !> Matrix to test.
      real(wp), intent(in) :: rot(3, 3)
      !> Tolerance on R^T R - I and det R - 1.
      real(wp), intent(in) :: tol
      logical :: ok
      real(wp) :: e(3, 3), det
      integer :: i
      e = matmul(transpose(rot), rot)
      do i = 1, 3
         e(i, i) = e(i, i) - 1.0_wp
      end do
      det = rot(1, 1) * (rot(2, 2) * rot(3, 3) - rot(2, 3) * rot(3, 2)) &
            - rot(1, 2) * (rot(2, 1) * rot(3, 3) - rot(2, 3) * rot(3, 1)) &
            + rot(1, 3) * (rot(2, 1) * rot(3, 2) - rot(2, 2) * rot(3, 1))
      ok = maxval(abs(e)) <= tol .and. abs(det - 1.0_wp) <= tol
   end function is_rotation
end module anm_geometry_rotation
