!> Local maximisation of a function of a direction on the unit sphere, by a compass (pattern)
!> search in the tangent plane: no pole singularity, no derivatives needed, robust on the rough
!> surfaces of real particles. Used to refine extents, the length and other extreme values found
!> first on a grid.
!>
!> Usage:
!>     call maximize_direction(f, u, step=0.02_wp, tol=1.0e-9_wp, fbest=fmax)
module anm_geometry_sphere_search
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: maximize_direction, tangent_basis, direction_function

   abstract interface
      !> A real function of a unit direction.
      function direction_function(u) result(f)
         import :: wp
         real(wp), intent(in) :: u(3)
         real(wp) :: f
      end function direction_function
   end interface

contains

   !> Orthonormal vectors e1, e2 perpendicular to the unit vector u.
   pure subroutine tangent_basis(u, e1, e2)
      !> Unit vector.
      real(wp), intent(in) :: u(3)
      !> Tangent vectors.
      real(wp), intent(out) :: e1(3), e2(3)
      real(wp) :: a(3)
      if (abs(u(1)) < 0.6_wp) then
         a = [1.0_wp, 0.0_wp, 0.0_wp]
      else
         a = [0.0_wp, 1.0_wp, 0.0_wp]
      end if
      e1 = a - dot_product(a, u) * u
      e1 = e1 / norm2(e1)
      e2 = [u(2) * e1(3) - u(3) * e1(2), u(3) * e1(1) - u(1) * e1(3), u(1) * e1(2) - u(2) * e1(1)]
   end subroutine tangent_basis

   !> Maximise f over unit directions near u (in place) by compass search: try the 8 neighbours
   !> at angular distance `step`, move to the best improvement, halve the step when none improves,
   !> stop when step < tol (radians).
   subroutine maximize_direction(f, u, step, tol, fbest)
      !> Function to maximise.
      procedure(direction_function) :: f
      !> Start direction on input, maximiser on output (unit).
      real(wp), intent(inout) :: u(3)
      !> Initial angular step (radians).
      real(wp), intent(in) :: step
      !> Final angular step (radians).
      real(wp), intent(in) :: tol
      !> Maximum value found.
      real(wp), intent(out) :: fbest
      real(wp) :: e1(3), e2(3), h, cand(3), fc, best(3), fnew
      real(wp), parameter :: dirs(2, 8) = reshape([1.0_wp, 0.0_wp, -1.0_wp, 0.0_wp, 0.0_wp, 1.0_wp, &
                                                   0.0_wp, -1.0_wp, 0.7071067811865476_wp, 0.7071067811865476_wp, &
                                                   -0.7071067811865476_wp, 0.7071067811865476_wp, &
                                                   0.7071067811865476_wp, -0.7071067811865476_wp, &
                                                   -0.7071067811865476_wp, -0.7071067811865476_wp], [2, 8])
      integer :: k, iter

      u = u / norm2(u)
      fbest = f(u)
      h = step
      do iter = 1, 10000
         if (h < tol) exit
         call tangent_basis(u, e1, e2)
         fnew = fbest
         best = u
         do k = 1, 8
            cand = u + h * (dirs(1, k) * e1 + dirs(2, k) * e2)
            cand = cand / norm2(cand)
            fc = f(cand)
            if (fc > fnew) then
               fnew = fc
               best = cand
            end if
         end do
         if (fnew > fbest) then
            fbest = fnew
            u = best
         else
            h = 0.5_wp * h
         end if
      end do
   end subroutine maximize_direction
end module anm_geometry_sphere_search
