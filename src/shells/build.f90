!> Uniform-thickness shells (thesis sections 2.3, 2.5.2, 3.2) of any thickness.
!>
!> The outer surface of a shell of thickness t is R_t(u) = max{rho : dist(rho u, particle) <= t}
!> along every direction u of a Gauss grid (`anm_shells_offset`: the thesis' Newton construction
!> from sampled starts, checked against sampled lower bounds, continuation across creases, the
!> definition itself as fallback), fitted by quadrature with an SH expansion of the smallest order
!> whose residual at the nodes is at most fit_tol * t (searched up to order_cap) and, by default,
!> lifted where it lies inside R_t until it lies inside by at most 0.02 t at every node. The
!> result is a star-shaped body about the same centre. Volumes are quadratures of R_t itself.
!>
!> Usage:
!>     type(sh_expansion_type) :: outer
!>     type(shell_report_type) :: rep
!>     call build_shell(shape, 0.02_wp * length, outer, rep, error, label="00002")
!>     call build_layers(shape, [t1, t2, t3], outers, reps, error, label="00002")
module anm_shells_build
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_shells_surface, only: shell_surface_type, new_shell_surface, grid_synthesis, grid_analysis
   use anm_shells_offset, only: offset_grid, offset_counts_type
   implicit none
   private

   public :: shell_report_type, build_shell, build_layers, default_shell_ntheta, default_fit_tol, &
      & default_order_cap

   !> Default number of polar nodes of the direction grid (the thesis' 120-point rule; nphi = 2 ntheta).
   integer, parameter :: default_shell_ntheta = 120
   !> Default fit tolerance: max |R_t - fitted| at the nodes, relative to t.
   real(wp), parameter :: default_fit_tol = 1.0e-3_wp
   !> Largest depth (relative to t) of the fitted surface inside R_t at the nodes: the one-sided
   !> correction lifts the fit until it holds, build_shell fails if it cannot. The fitted body thus
   !> contains the true dilated body up to 0.02 t at the nodes (the safe side for exclusion).
   real(wp), parameter :: inside_tol = 0.02_wp
   !> Largest accepted distance of the fitted surface from R_t at the nodes is the larger of
   !> max_outside t and max_outside_radius rmax. With the lift the distance is outward (the
   !> dilated body has creases, concave kinks, in concave regions, and the smooth fit fills their
   !> valleys): measured up to 1.7 t on synthetic shapes at degree 14-20 and t = 0.5 % of L, up to
   !> 0.75 t on MA111-7-coarse at degree 14, and up to 6 t (0.6 % of L) at degree 30 and
   !> t = 0.1 % of L, where the crevices of the particle are sharper than t.
   real(wp), parameter :: max_outside = 3.0_wp
   !> See max_outside: the bound relative to the largest particle radius.
   real(wp), parameter :: max_outside_radius = 0.02_wp
   !> Largest number of lifting iterations of the one-sided correction.
   integer, parameter :: max_lifts = 40
   !> Relaxation factor of the first lifting iteration.
   real(wp), parameter :: lift_factor = 2.0_wp
   !> Largest relaxation factor: the factor doubles after every lift that less than halves the
   !> deepest violation (narrow crease deficits are spread thinly by the projection).
   real(wp), parameter :: max_lift_factor = 16.0_wp

   !> What happened while building one shell (lengths in shape units).
   type :: shell_report_type
      !> Thickness t.
      real(wp) :: thickness = 0.0_wp
      !> Directions of the grid (ntheta * nphi).
      integer :: directions = 0
      !> Directions solved by the thesis' Newton construction (root validated).
      integer :: newton = 0
      !> Directions that needed the distance-definition fallback.
      integer :: fallback = 0
      !> Newton directions whose root came from a neighbour's foot (continuation across creases).
      integer :: continued = 0
      !> Exact evaluations of the particle expansion spent in the Newton iterations.
      integer :: evaluations = 0
      !> Order of the fitted outer expansion.
      integer :: order = 0
      !> Largest |R_t - fitted| over the grid nodes.
      real(wp) :: fit_residual = 0.0_wp
      !> Largest depth of the fitted surface inside R_t over the grid nodes (<= inside_tol t).
      real(wp) :: fit_inside = 0.0_wp
      !> Largest height of the fitted surface outside R_t over the grid nodes.
      real(wp) :: fit_outside = 0.0_wp
      !> Lifting iterations of the one-sided correction (0 where the plain fit lies inside R_t by
      !> at most inside_tol t).
      integer :: lifts = 0
      !> Volume of the particle (grid quadrature of r^3 / 3).
      real(wp) :: particle_volume = 0.0_wp
      !> Volume of the particle + shell body, the dilated body (grid quadrature of R_t^3 / 3 at the
      !> nodes: the definition, not the fitted surface).
      real(wp) :: outer_volume = 0.0_wp
      !> Volume enclosed by the fitted outer surface (>= outer_volume when lifted).
      real(wp) :: fitted_volume = 0.0_wp
      !> Shell volume, outer_volume - particle_volume.
      real(wp) :: shell_volume = 0.0_wp
      !> Shell volume fraction of the particle + shell body, shell_volume / outer_volume.
      real(wp) :: shell_fraction = 0.0_wp
      !> Volume of this layer: outer_volume minus the volume inside the previous layer (the
      !> particle for the first); equals shell_volume for a single shell.
      real(wp) :: layer_volume = 0.0_wp
      !> layer_volume over the volume inside the outermost layer built together with it.
      real(wp) :: layer_fraction = 0.0_wp
   end type shell_report_type

contains

   !> Default largest order tried for the fit: twice the particle's degree, at least 24,
   !> at most ntheta - 1.
   elemental function default_order_cap(nmax, ntheta) result(cap)
      !> Degree of the particle expansion.
      integer, intent(in) :: nmax
      !> Polar nodes of the grid.
      integer, intent(in) :: ntheta
      integer :: cap
      cap = min(ntheta - 1, max(2 * nmax, 24))
   end function default_order_cap

   !> Build the outer surface of the shell of thickness t around `shape`.
   subroutine build_shell(shape, thickness, outer, report, error, label, ntheta, order, fit_tol, conservative)
      !> Particle expansion (body frame, shape units; star-shaped about its centre).
      type(sh_expansion_type), intent(in) :: shape
      !> Thickness t > 0, shape units.
      real(wp), intent(in) :: thickness
      !> Outer surface of the shell, a star-shaped expansion about the same centre.
      type(sh_expansion_type), intent(out) :: outer
      !> Counts, residual, order and volumes.
      type(shell_report_type), intent(out) :: report
      !> Error naming the particle and the thickness when the shell cannot be built.
      type(error_type), allocatable, intent(out) :: error
      !> Name of the particle for messages (default "particle").
      character(len=*), intent(in), optional :: label
      !> Polar nodes of the direction grid (default 120; nphi = 2 ntheta).
      integer, intent(in), optional :: ntheta
      !> Fixed order of the fitted outer surface (default: smallest order meeting fit_tol, up to
      !> default_order_cap).
      integer, intent(in), optional :: order
      !> Fit tolerance relative to t (default 1e-3).
      real(wp), intent(in), optional :: fit_tol
      !> Lift the fit where it lies inside R_t (default true): the fitted body then contains the
      !> dilated body up to 0.02 t at the nodes. False: the plain quadrature fit (residual of either
      !> sign, at most 3 t), e.g. to build shells on shells without accumulating the lifts.
      logical, intent(in), optional :: conservative
      type(shell_surface_type) :: surf
      character(len=:), allocatable :: name
      integer :: nt, cap
      logical :: lift

      name = "particle"
      if (present(label)) name = label
      lift = .true.
      if (present(conservative)) lift = conservative
      nt = default_shell_ntheta
      if (present(ntheta)) nt = ntheta
      cap = default_order_cap(shape%nmax, nt)
      if (present(order)) cap = order
      if (.not. (thickness > 0.0_wp .and. thickness < huge(thickness))) then
         call fatal_error(error, "shell of "//name//": thickness must be positive and finite, got "// &
                          to_string(thickness), error_code%value)
         return
      end if
      if (nt < 4 .or. cap < 0 .or. cap >= nt) then
         call fatal_error(error, "shell of "//name//": grid of "//to_string(nt)//" polar nodes cannot fit order "// &
                          to_string(cap), error_code%value)
         return
      end if
      call prepare_surface(surf, shape, nt, cap, thickness, name, error)
      if (allocated(error)) return
      call shell_on_surface(surf, thickness, cap, .not. present(order), fit_tol, lift, name, outer, report, error)
   end subroutine build_shell

   !> The surface data of `shape` on an nt x 2 nt grid with tables to degree cap; an error naming
   !> the particle when it is not star-shaped about its centre.
   pure subroutine prepare_surface(surf, shape, nt, cap, thickness, name, error)
      type(shell_surface_type), intent(out) :: surf
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: nt, cap
      real(wp), intent(in) :: thickness
      character(len=*), intent(in) :: name
      type(error_type), allocatable, intent(out) :: error

      call new_shell_surface(surf, shape, nt, cap)
      if (.not. surf%rmin > 0.0_wp) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): particle is not star-shaped "// &
                          "about its centre (r = "//to_string(surf%rmin)//")", error_code%not_star)
      end if
   end subroutine prepare_surface

   !> Outer radii, fit and acceptance of one shell of thickness t on prepared surface data.
   pure subroutine shell_on_surface(surf, thickness, cap, search, fit_tol, lift, name, outer, report, error)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: thickness
      integer, intent(in) :: cap
      logical, intent(in) :: search
      real(wp), intent(in), optional :: fit_tol
      logical, intent(in) :: lift
      character(len=*), intent(in) :: name
      type(sh_expansion_type), intent(out) :: outer
      type(shell_report_type), intent(out) :: report
      type(error_type), allocatable, intent(out) :: error
      real(wp), allocatable :: rt(:, :)
      real(wp) :: bound
      integer :: nt

      nt = surf%grid%sphere%ntheta
      allocate (rt(nt, 2 * nt))
      call outer_radii(surf, thickness, rt, report)
      if (.not. all(rt >= surf%r .and. rt < huge(1.0_wp))) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): outer radius not found "// &
                          "in some directions")
         return
      end if
      call fit_outer(surf, rt, cap, search, thickness, fit_tol, lift, outer, report)
      if (lift .and. report%fit_inside > inside_tol * thickness) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): fitted surface lies "// &
                          to_string(report%fit_inside)//" inside R_t at order "//to_string(report%order)// &
                          " after "//to_string(report%lifts)//" lifts (bound "//to_string(inside_tol)// &
                          " t); use a finer grid or higher order")
         return
      end if
      bound = max(max_outside * thickness, max_outside_radius * surf%rmax)
      if (report%fit_residual > bound) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): fitted surface lies "// &
                          to_string(report%fit_residual)//" from R_t at order "//to_string(report%order)// &
                          " (bound "//to_string(bound)//" = max("//to_string(max_outside)//" t, "// &
                          to_string(max_outside_radius)//" rmax)); use a finer grid or higher order")
         return
      end if
   end subroutine shell_on_surface

   !> Build nested layers at cumulative distances t_1 < t_2 < ... from the particle surface.
   !> Each layer's outer surface is built from the particle itself (exact distances, no
   !> accumulation of fit errors); reports(k)%layer_volume is the volume between layers k-1 and k
   !> and reports(k)%layer_fraction that volume over the volume inside the outermost layer.
   subroutine build_layers(shape, thicknesses, outers, reports, error, label, ntheta, order, fit_tol, conservative)
      !> Particle expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Cumulative distances from the particle surface, strictly increasing, shape units.
      real(wp), intent(in) :: thicknesses(:)
      !> Outer surfaces of the layers.
      type(sh_expansion_type), allocatable, intent(out) :: outers(:)
      !> One report per layer.
      type(shell_report_type), allocatable, intent(out) :: reports(:)
      !> Error naming the particle and the offending thickness.
      type(error_type), allocatable, intent(out) :: error
      !> Name of the particle for messages.
      character(len=*), intent(in), optional :: label
      !> Polar nodes of the direction grid (default 120).
      integer, intent(in), optional :: ntheta
      !> Fixed order of the fitted outer surfaces.
      integer, intent(in), optional :: order
      !> Fit tolerance relative to each layer's t.
      real(wp), intent(in), optional :: fit_tol
      !> Lift the fits where they lie inside R_t (default true; see build_shell).
      logical, intent(in), optional :: conservative
      character(len=:), allocatable :: name
      type(shell_surface_type) :: surf
      real(wp) :: inner
      integer :: k, nl, nt, cap
      logical :: lift

      name = "particle"
      if (present(label)) name = label
      lift = .true.
      if (present(conservative)) lift = conservative
      nl = size(thicknesses)
      if (nl < 1) then
         call fatal_error(error, "layers of "//name//": no thickness given", error_code%value)
         return
      end if
      do k = 2, nl
         if (.not. thicknesses(k) > thicknesses(k - 1)) then
            call fatal_error(error, "layers of "//name//": thicknesses must increase, got t("//to_string(k)//") = "// &
                             to_string(thicknesses(k))//" after "//to_string(thicknesses(k - 1)), error_code%value)
            return
         end if
      end do
      if (.not. (thicknesses(1) > 0.0_wp .and. thicknesses(nl) < huge(1.0_wp))) then
         call fatal_error(error, "layers of "//name//": thicknesses must be positive and finite, got "// &
                          to_string(thicknesses(1))//" .. "//to_string(thicknesses(nl)), error_code%value)
         return
      end if
      nt = default_shell_ntheta
      if (present(ntheta)) nt = ntheta
      cap = default_order_cap(shape%nmax, nt)
      if (present(order)) cap = order
      if (nt < 4 .or. cap < 0 .or. cap >= nt) then
         call fatal_error(error, "layers of "//name//": grid of "//to_string(nt)//" polar nodes cannot fit order "// &
                          to_string(cap), error_code%value)
         return
      end if
      ! one surface for all layers (the particle is the same)
      call prepare_surface(surf, shape, nt, cap, thicknesses(1), name, error)
      if (allocated(error)) return
      allocate (outers(nl), reports(nl))
      do k = 1, nl
         call shell_on_surface(surf, thicknesses(k), cap, .not. present(order), fit_tol, lift, &
                               name//" layer "//to_string(k), outers(k), reports(k), error)
         if (allocated(error)) return
      end do
      inner = reports(1)%particle_volume
      do k = 1, nl
         reports(k)%layer_volume = reports(k)%outer_volume - inner
         reports(k)%layer_fraction = reports(k)%layer_volume / reports(nl)%outer_volume
         inner = reports(k)%outer_volume
      end do
   end subroutine build_layers

   !> R_t at every node of the surface's grid, with the Newton/fallback counts.
   pure subroutine outer_radii(surf, t, rt, report)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: t
      real(wp), intent(out) :: rt(:, :)
      type(shell_report_type), intent(inout) :: report
      type(offset_counts_type) :: counts

      call offset_grid(surf, t, rt, counts)
      report%thickness = t
      report%directions = size(rt)
      report%newton = counts%newton
      report%fallback = counts%fallback
      report%continued = counts%continued
      report%evaluations = counts%evaluations
   end subroutine outer_radii

   !> Fit R_t by quadrature: order `cap`, or (search) the smallest order <= cap whose residual at
   !> the nodes is at most fit_tol * t (bisection on the order; the residual decreases with it).
   pure subroutine fit_outer(surf, rt, cap, search, t, fit_tol, lift, outer, report)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: rt(:, :)
      integer, intent(in) :: cap
      logical, intent(in) :: search
      real(wp), intent(in) :: t
      real(wp), intent(in), optional :: fit_tol
      logical, intent(in) :: lift
      type(sh_expansion_type), intent(out) :: outer
      type(shell_report_type), intent(inout) :: report
      real(wp), allocatable :: a(:, :), b(:, :), fit(:, :), da(:, :), db(:, :), deficit(:, :)
      real(wp) :: target, res, factor, worst, previous
      integer :: lo, hi, mid, best
      logical :: have_fit

      target = default_fit_tol * t
      if (present(fit_tol)) target = fit_tol * t
      allocate (a(0:cap, 0:cap), b(0:cap, 0:cap), fit(size(rt, 1), size(rt, 2)))
      call grid_analysis(surf%grid, rt, cap, a, b)
      best = cap
      have_fit = .false.
      if (search) then
         call grid_synthesis(surf%grid, a, b, cap, fit)
         res = maxval(abs(rt - fit))
         have_fit = .true.
         if (res <= target) then
            have_fit = .false.
            lo = 0
            hi = cap
            do while (lo < hi)
               mid = (lo + hi) / 2
               call grid_synthesis(surf%grid, a, b, mid, fit)
               if (maxval(abs(rt - fit)) <= target) then
                  hi = mid
               else
                  lo = mid + 1
               end if
            end do
            best = lo
         end if
      end if
      if (.not. have_fit) then
         ! (otherwise fit already holds the full order cap)
         call grid_synthesis(surf%grid, a, b, best, fit)
      end if
      ! one-sided correction: lift the fit where it lies inside R_t (creases) until it lies inside
      ! by at most inside_tol t at every node
      allocate (da(0:best, 0:best), db(0:best, 0:best), deficit(size(rt, 1), size(rt, 2)))
      report%lifts = 0
      factor = lift_factor
      worst = maxval(rt - fit)
      do while (lift .and. worst > inside_tol * t .and. report%lifts < max_lifts)
         ! only the nodes that violate the bound, lifted to half of it (little overshoot)
         deficit = max(0.0_wp, rt - fit - 0.5_wp * inside_tol * t)
         ! sums over the violating nodes only when they are few (cost per node ~ 2 order against
         ! ~ 2 nphi order per grid row for the dense transform)
         if (4 * count(deficit > 0.0_wp) < size(rt)) then
            call sparse_analyze(surf, deficit, best, da, db)
         else
            call grid_analysis(surf%grid, deficit, best, da, db)
         end if
         a(0:best, 0:best) = a(0:best, 0:best) + factor * da
         b(0:best, 0:best) = b(0:best, 0:best) + factor * db
         call grid_synthesis(surf%grid, a, b, best, fit)
         report%lifts = report%lifts + 1
         previous = worst
         worst = maxval(rt - fit)
         ! slow progress (the projection spreads a narrow deficit thinly): lift harder next time
         if (worst > 0.5_wp * previous) factor = min(max_lift_factor, 2.0_wp * factor)
      end do
      call new_sh_expansion_real(outer, a(0:best, 0:best), b(0:best, 0:best))
      report%order = best
      report%fit_residual = maxval(abs(rt - fit))
      report%fit_inside = max(0.0_wp, maxval(rt - fit))
      report%fit_outside = max(0.0_wp, maxval(fit - rt))
      report%particle_volume = grid_volume(surf, surf%r)
      report%outer_volume = grid_volume(surf, rt)
      report%fitted_volume = grid_volume(surf, fit)
      report%shell_volume = report%outer_volume - report%particle_volume
      report%shell_fraction = report%shell_volume / report%outer_volume
      report%layer_volume = report%shell_volume
      report%layer_fraction = report%shell_fraction
   end subroutine fit_outer

   !> `grid_analysis` of a function that vanishes at most nodes (the deficit of a lift): per ring,
   !> the azimuthal sums over its nonzero nodes only, then the Legendre sums for the rings that
   !> have any.
   pure subroutine sparse_analyze(surf, f, nmax, a, b)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: f(:, :)
      integer, intent(in) :: nmax
      real(wp), intent(out) :: a(0:, 0:), b(0:, 0:)
      real(wp) :: cs(0:nmax), ss(0:nmax), wf
      integer :: i, j, m, k0, lm
      logical :: nonzero

      a = 0.0_wp
      b = 0.0_wp
      lm = surf%grid%lmax
      do i = 1, size(f, 1)
         cs = 0.0_wp
         ss = 0.0_wp
         nonzero = .false.
         do j = 1, size(f, 2)
            if (f(i, j) == 0.0_wp) cycle
            nonzero = .true.
            wf = 2.0_wp * f(i, j) * surf%grid%sphere%weight(i)
            cs = cs + wf * surf%grid%trig(1:nmax + 1, j)
            ss(1:nmax) = ss(1:nmax) + wf * surf%grid%trig(lm + 2:lm + 1 + nmax, j)
         end do
         if (.not. nonzero) cycle
         ! (order 0 carries the weight once)
         cs(0) = 0.5_wp * cs(0)
         do m = 0, nmax
            k0 = surf%grid%idx(m)
            a(m:nmax, m) = a(m:nmax, m) + cs(m) * surf%grid%plm(k0:k0 + nmax - m, i)
            if (m > 0) b(m:nmax, m) = b(m:nmax, m) + ss(m) * surf%grid%plm(k0:k0 + nmax - m, i)
         end do
      end do
   end subroutine sparse_analyze

   !> Volume inside the radii r(i, j) given on the grid nodes: sum of w r^3 / 3.
   pure function grid_volume(surf, r) result(vol)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: r(:, :)
      real(wp) :: vol
      integer :: j
      vol = 0.0_wp
      do j = 1, size(r, 2)
         vol = vol + sum(surf%grid%sphere%weight * r(:, j)**3) / 3.0_wp
      end do
   end function grid_volume
end module anm_shells_build
