!> The shell layers of one particle evaluated together, and a certified direction table that
!> decides most points around the particle without any evaluation.
!>
!> The K layer surfaces of a particle (thesis section 3.3 masks) share the particle's body frame,
!> so along one direction u all K radii r_k(u) come from one Legendre column recursion and one
!> set of cos(m phi), sin(m phi): `stack_radii` runs the recursion of `radius_xs` (`sh_sum_forms` of `anm_sh_kernel`)
!> (anm_sh_expansion) once and accumulates the K forms side by side (the coefficients are stored
!> form-fastest, so the accumulation is a short vector operation). Forms of lower degree are
!> padded with zeros, which adds exact zeros: each r_k is the same sum as its own radius_dir.
!>
!> Direction table (`build_stack_table`). On a (theta, phi) grid of spacing h in both angles the
!> radii of the particle and of every layer are evaluated at the nodes. Along a meridian or a
!> parallel the degree-n part of r is a trigonometric polynomial of degree n, so by Bernstein's
!> inequality its second derivative is at most n^2 max|r_n| <= n^2 ||c_n|| sqrt((2n+1)/(4 pi))
!> (||c_n|| the norm of the orthonormal coefficients of degree n; addition theorem and
!> Cauchy-Schwarz). Summed over n this bounds r_thetatheta and r_phiphi by H (`curvature_bound`),
!> and the bilinear interpolation error on a cell by H (h_theta^2 + h_phi^2) / 8. Hence per cell
!> lo = min over the 4 corners of r_particle - that error and hp = max + that error bound the
!> particle radius, and hi = max over corners and forms of r + its error bounds every radius: a
!> point with |y| <= lo is inside the particle, one with |y| > hp outside it, and one with
!> |y| > hi outside the particle and every layer, without evaluation. Only points in the bands
!> around the surfaces need radii.
!>
!> Usage:
!>     call new_slice_stack(stack, layers)             ! layers(k): outer surface of layer k
!>     call stack_radii(stack, y, r)                   ! r(k) = layers(k)%radius_dir(y)
!>     call build_stack_table(stack, particle, layers, margin)
!>     call stack_table_bounds(stack, y, lo, hp, hi)
module anm_slicing_stack
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_legendre, only: legendre_table_type, new_legendre_table
   use anm_sh_kernel, only: sh_sum_forms
   implicit none
   private

   public :: slice_stack_type, new_slice_stack, stack_radii, curvature_bound, build_stack_table, &
      & stack_table_bounds, table_nodes, min_table_polar, max_table_polar

   !> Fewest and most polar intervals of a direction table (the azimuth has twice as many).
   integer, parameter :: min_table_polar = 8, max_table_polar = 256
   !> Relative safety added to the table bounds against rounding in the radii and the cell lookup.
   real(wp), parameter :: table_slack = 1.0e-9_wp

   !> Layer surfaces of one particle, evaluated together (immutable once built; shared by threads).
   type :: slice_stack_type
      !> Number of forms and that number rounded up to a multiple of 4.
      integer :: nform = 0, npad = 0
      !> Highest degree of the forms.
      integer :: nmax = -1
      !> Coefficients (2 npad, 0:nmax, 0:nmax) indexed (form, n, m): cosine coefficients of form k
      !> at k, sine coefficients at npad + k; zero beyond a form's degree and for padding.
      real(wp), allocatable :: c(:, :, :)
      !> Legendre recursion of degree nmax + 1 (as the forms' own).
      type(legendre_table_type) :: table
      !> Polar and azimuthal cells of the direction table (0: no table) and their angles.
      integer :: ntheta = 0, nphi = 0
      real(wp) :: dtheta = 0.0_wp, dphi = 0.0_wp
      !> Per cell (nphi, ntheta): lower and upper bound of the particle radius, upper bound of
      !> every radius (particle and layers).
      real(wp), allocatable :: lo(:, :), hp(:, :), hi(:, :)
   end type slice_stack_type

contains

   !> A stack of forms (e.g. the outer surfaces of a particle's layers, innermost first).
   pure subroutine new_slice_stack(stack, forms)
      !> Stack to build.
      type(slice_stack_type), intent(out) :: stack
      !> Expansions in one body frame.
      type(sh_expansion_type), intent(in) :: forms(:)
      integer :: k, n, m, nf, np

      nf = size(forms)
      np = 4 * ((nf + 3) / 4)
      stack%nform = nf
      stack%npad = np
      stack%nmax = 0
      do k = 1, nf
         stack%nmax = max(stack%nmax, forms(k)%nmax)
      end do
      allocate (stack%c(2 * np, 0:stack%nmax, 0:stack%nmax))
      stack%c = 0.0_wp
      do k = 1, nf
         do m = 0, forms(k)%nmax
            do n = m, forms(k)%nmax
               stack%c(k, n, m) = forms(k)%a(n, m)
               stack%c(np + k, n, m) = forms(k)%b(n, m)
            end do
         end do
      end do
      stack%table = new_legendre_table(stack%nmax + 1)
   end subroutine new_slice_stack

   !> Radii of every form of the stack along the direction of y (body frame, non-zero, need not
   !> be normalised): one column recursion shared by the forms (see the module doc).
   pure subroutine stack_radii(stack, y, r)
      !> Stack.
      type(slice_stack_type), intent(in) :: stack
      !> Direction.
      real(wp), intent(in) :: y(3)
      !> r(k) of form k, size >= nform.
      real(wp), intent(inout) :: r(:)
      real(wp) :: racc(stack%npad)
      real(wp) :: rho, len, x, s, cp, sp

      len = sqrt(y(1)**2 + y(2)**2 + y(3)**2)
      rho = sqrt(y(1)**2 + y(2)**2)
      x = y(3) / len
      s = rho / len
      if (rho > 0.0_wp) then
         cp = y(1) / rho
         sp = y(2) / rho
      else
         cp = 1.0_wp
         sp = 0.0_wp
      end if
      call sh_sum_forms(stack%table, stack%c, stack%npad, stack%nmax, x, s, cp, sp, racc)
      r(1:stack%nform) = racc(1:stack%nform)
   end subroutine stack_radii

   !> H = sum_n n^2 ||c_n|| sqrt((2n+1)/(4 pi)): a bound on the second derivative of r along any
   !> great circle and any parallel (Bernstein's inequality per degree; see the module doc).
   pure function curvature_bound(sh) result(h)
      !> Expansion.
      type(sh_expansion_type), intent(in) :: sh
      real(wp) :: h
      real(wp) :: c2
      integer :: n
      h = 0.0_wp
      do n = 1, sh%nmax
         c2 = sh%a(n, 0)**2 + 0.5_wp * (sum(sh%a(n, 1:n)**2) + sum(sh%b(n, 1:n)**2))
         h = h + real(n, wp)**2 * sqrt(c2 * (2 * n + 1) / (4.0_wp * pi))
      end do
   end function curvature_bound

   !> Polar intervals of a table whose interpolation error is at most `margin` for curvature
   !> bound h (clamped to [min_table_polar, max_table_polar]); the table has
   !> (ntheta + 1) (2 ntheta + 1) nodes.
   pure function table_nodes(h, margin) result(ntheta)
      !> Largest curvature bound of the forms.
      real(wp), intent(in) :: h
      !> Largest interpolation error wanted (shape units, > 0).
      real(wp), intent(in) :: margin
      integer :: ntheta
      real(wp) :: step
      ! error = h (dtheta^2 + dphi^2) / 8 with dtheta = dphi = step
      if (h <= 0.0_wp) then
         ntheta = min_table_polar
         return
      end if
      step = sqrt(4.0_wp * margin / h)
      ntheta = min(max_table_polar, max(min_table_polar, ceiling(pi / step)))
   end function table_nodes

   !> Build the direction table of a stack: certified per-cell lower bound of the particle radius
   !> and upper bound of the particle's and every layer's radius (see the module doc).
   subroutine build_stack_table(stack, particle, layers, ntheta)
      !> Stack of the layers (built from `layers`).
      type(slice_stack_type), intent(inout) :: stack
      !> The particle.
      type(sh_expansion_type), intent(in) :: particle
      !> The layers of the stack.
      type(sh_expansion_type), intent(in) :: layers(:)
      !> Polar intervals (the azimuth gets 2 ntheta).
      integer, intent(in) :: ntheta
      real(wp), allocatable :: nlo(:, :), nhp(:, :), nhi(:, :)
      real(wp) :: err_p, err_l, hl, u(3), th, ph, rp, rmax, step2
      real(wp), allocatable :: r(:)
      integer :: i, j, k, nph

      nph = 2 * ntheta
      stack%ntheta = ntheta
      stack%nphi = nph
      stack%dtheta = pi / ntheta
      stack%dphi = two_pi / nph
      step2 = stack%dtheta**2 + stack%dphi**2
      err_p = curvature_bound(particle) * step2 / 8.0_wp
      hl = 0.0_wp
      do k = 1, size(layers)
         hl = max(hl, curvature_bound(layers(k)))
      end do
      err_l = hl * step2 / 8.0_wp
      allocate (nlo(0:nph, 0:ntheta), nhp(0:nph, 0:ntheta), nhi(0:nph, 0:ntheta))
      !$omp parallel default(none) private(i, j, u, th, ph, rp, rmax, r) &
      !$omp shared(stack, particle, ntheta, nph, err_p, err_l, nlo, nhp, nhi)
      allocate (r(max(1, stack%npad)))
      !$omp do schedule(dynamic, 1)
      do i = 0, ntheta
         th = i * stack%dtheta
         do j = 0, nph - 1
            ph = j * stack%dphi
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            rp = particle%radius_dir(u)
            rmax = rp + err_p
            if (stack%nform > 0) then
               call stack_radii(stack, u, r)
               rmax = max(rmax, maxval(r(1:stack%nform)) + err_l)
            end if
            nlo(j, i) = rp - err_p
            nhp(j, i) = rp + err_p
            nhi(j, i) = rmax
         end do
         nlo(nph, i) = nlo(0, i)
         nhp(nph, i) = nhp(0, i)
         nhi(nph, i) = nhi(0, i)
      end do
      !$omp end do
      !$omp end parallel
      allocate (stack%lo(nph, ntheta), stack%hp(nph, ntheta), stack%hi(nph, ntheta))
      do i = 1, ntheta
         do j = 1, nph
            stack%lo(j, i) = min(nlo(j - 1, i - 1), nlo(j, i - 1), nlo(j - 1, i), nlo(j, i))
            stack%hp(j, i) = max(nhp(j - 1, i - 1), nhp(j, i - 1), nhp(j - 1, i), nhp(j, i))
            stack%hi(j, i) = max(nhi(j - 1, i - 1), nhi(j, i - 1), nhi(j - 1, i), nhi(j, i))
            stack%lo(j, i) = stack%lo(j, i) - table_slack * (1.0_wp + abs(stack%lo(j, i)))
            stack%hp(j, i) = stack%hp(j, i) + table_slack * (1.0_wp + abs(stack%hp(j, i)))
            stack%hi(j, i) = stack%hi(j, i) + table_slack * (1.0_wp + abs(stack%hi(j, i)))
         end do
      end do
   end subroutine build_stack_table

   !> Certified bounds at the direction of y (body frame, non-zero) from the table: the particle's
   !> radius lies in [lo, hp], every radius of the stack and the particle's is <= hi. Without a
   !> table lo = -huge and hp = hi = huge.
   pure subroutine stack_table_bounds(stack, y, lo, hp, hi)
      !> Stack with its table.
      type(slice_stack_type), intent(in) :: stack
      !> Direction.
      real(wp), intent(in) :: y(3)
      !> Bounds.
      real(wp), intent(out) :: lo, hp, hi
      real(wp) :: th, ph, len
      integer :: i, j
      if (stack%ntheta == 0) then
         lo = -huge(1.0_wp)
         hp = huge(1.0_wp)
         hi = huge(1.0_wp)
         return
      end if
      len = sqrt(y(1)**2 + y(2)**2 + y(3)**2)
      th = acos(max(-1.0_wp, min(1.0_wp, y(3) / len)))
      ph = atan2(y(2), y(1))
      if (ph < 0.0_wp) ph = ph + two_pi
      i = min(stack%ntheta, max(1, 1 + int(th / stack%dtheta)))
      j = min(stack%nphi, max(1, 1 + int(ph / stack%dphi)))
      lo = stack%lo(j, i)
      hp = stack%hp(j, i)
      hi = stack%hi(j, i)
   end subroutine stack_table_bounds
end module anm_slicing_stack
