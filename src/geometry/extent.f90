!> Extent boxes: the lowest and highest coordinate of the surface along x, y, z (body frame,
!> measured from the particle centre).
!>
!> Two modes: the thesis' angular scan with N_ext angles in theta and in phi (cheap, slightly
!> inside the true box), and a refined mode that starts from a Gauss-grid scan and maximises
!> each of the six support values with a tangent-plane compass search to an angular tolerance.
!>
!> Usage:
!>     call extent_scan(shape, 40, lo, hi)           ! thesis N_ext = 40
!>     call extent_refined(shape, grid, lo, hi)      ! accurate to rounding in practice
module anm_geometry_extent
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_grid, only: sh_grid_type, sh_synthesize
   use anm_geometry_sphere_search, only: maximize_direction
   implicit none
   private

   public :: extent_scan, extent_refined

contains

   !> Thesis extent box: theta_i = pi i/(next-1), i = 0..next-1 (poles included),
   !> phi_j = 2 pi j/next, j = 0..next-1; the box of the next^2 surface points.
   pure subroutine extent_scan(shape, next, lo, hi)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Number of angles in theta and in phi (N_ext >= 2).
      integer, intent(in) :: next
      !> Lowest and highest x, y, z.
      real(wp), intent(out) :: lo(3), hi(3)
      integer :: i, j
      real(wp) :: th, ph, u(3), x(3)
      lo = huge(1.0_wp)
      hi = -huge(1.0_wp)
      do i = 0, next - 1
         th = pi * i / real(max(1, next - 1), wp)
         do j = 0, next - 1
            ph = two_pi * j / real(next, wp)
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            x = shape%radius_dir(u) * u
            lo = min(lo, x)
            hi = max(hi, x)
         end do
      end do
   end subroutine extent_scan

   !> Refined extent box: for each of the six axis directions d, maximise d . x(u) over unit u,
   !> starting from the best node of the Gauss grid and from the direction d itself, with a compass
   !> search to angular tolerance `tol` (default 1e-10 rad).
   subroutine extent_refined(shape, grid, lo, hi, tol)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Grid for the starting scan.
      type(sh_grid_type), intent(in) :: grid
      !> Lowest and highest x, y, z.
      real(wp), intent(out) :: lo(3), hi(3)
      !> Angular tolerance (radians).
      real(wp), intent(in), optional :: tol
      real(wp), allocatable :: r(:, :)
      real(wp) :: d(3), u(3), best, val, tl, ub(3)
      integer :: k, sgn, i, j, nt, np, ncand, c
      integer, parameter :: nstart = 4
      real(wp) :: cand_val(nstart), cand_u(3, nstart)

      tl = 1.0e-10_wp
      if (present(tol)) tl = tol
      nt = grid%sphere%ntheta
      np = grid%sphere%nphi
      allocate (r(nt, np))
      call sh_synthesize(grid, shape, r)
      do k = 1, 3
         do sgn = -1, 1, 2
            d = 0.0_wp
            d(k) = real(sgn, wp)
            ! keep the nstart best grid nodes as starting points
            cand_val = -huge(1.0_wp)
            ncand = 0
            do j = 1, np
               do i = 1, nt
                  u = node(i, j)
                  val = r(i, j) * dot_product(d, u)
                  if (val > cand_val(nstart)) then
                     c = nstart
                     do while (c > 1)
                        if (cand_val(c - 1) >= val) exit
                        cand_val(c) = cand_val(c - 1)
                        cand_u(:, c) = cand_u(:, c - 1)
                        c = c - 1
                     end do
                     cand_val(c) = val
                     cand_u(:, c) = u
                     ncand = min(nstart, ncand + 1)
                  end if
               end do
            end do
            best = -huge(1.0_wp)
            do c = 1, ncand + 1
               if (c <= ncand) then
                  ub = cand_u(:, c)
               else
                  ub = d
               end if
               call maximize_direction(support, ub, 0.5_wp * pi / nt, tl, val)
               best = max(best, val)
            end do
            if (sgn < 0) then
               lo(k) = -best
            else
               hi(k) = best
            end if
         end do
      end do
   contains
      function support(uu) result(f)
         real(wp), intent(in) :: uu(3)
         real(wp) :: f
         f = shape%radius_dir(uu) * dot_product(d, uu)
      end function support

      pure function node(ii, jj) result(uu)
         integer, intent(in) :: ii, jj
         real(wp) :: uu(3)
         uu = [grid%sphere%sint(ii) * grid%trig(2, jj), grid%sphere%sint(ii) * grid%trig(grid%lmax + 2, jj), &
               grid%sphere%x(ii)]
      end function node
   end subroutine extent_refined
end module anm_geometry_extent
