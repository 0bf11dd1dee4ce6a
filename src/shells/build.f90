!> Uniform-thickness shells (thesis sections 2.3, 2.5.2, 3.2) of any thickness.
!>
!> The outer surface of a shell of thickness t is R_t(u) = max{rho : dist(rho u, particle) <= t}
!> along every direction u of a Gauss grid (`anm_shells_offset`: the thesis' Newton construction,
!> validated against that definition, with the definition itself as fallback), fitted by
!> quadrature with an SH expansion of the smallest order whose residual at the nodes is at most
!> fit_tol * t (searched up to order_cap). The result is a star-shaped body about the same centre.
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
   use anm_sh_grid, only: sh_analyze, sh_synthesize
   use anm_shells_surface, only: shell_surface_type, new_shell_surface
   use anm_shells_offset, only: offset_grid, offset_counts_type
   implicit none
   private

   public :: shell_report_type, build_shell, build_layers, default_shell_ntheta, default_fit_tol, &
      & default_order_cap

   !> Default number of polar nodes of the direction grid (the thesis' 120-point rule; nphi = 2 ntheta).
   integer, parameter :: default_shell_ntheta = 120
   !> Default fit tolerance: max |R_t - fitted| at the nodes, relative to t.
   real(wp), parameter :: default_fit_tol = 1.0e-3_wp
   !> Largest accepted fit residual relative to t: above it build_shell fails (the dilated body has
   !> creases in concave regions, which a smooth fit resolves only slowly with the order).
   real(wp), parameter :: max_fit_residual = 0.5_wp

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
      !> Volume of the particle (grid quadrature of r^3 / 3).
      real(wp) :: particle_volume = 0.0_wp
      !> Volume enclosed by the fitted outer surface.
      real(wp) :: outer_volume = 0.0_wp
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
   subroutine build_shell(shape, thickness, outer, report, error, label, ntheta, order, fit_tol)
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
      type(shell_surface_type) :: surf
      character(len=:), allocatable :: name
      real(wp), allocatable :: rt(:, :)
      integer :: nt, cap

      name = "particle"
      if (present(label)) name = label
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
      call new_shell_surface(surf, shape, nt, cap)
      if (.not. surf%rmin > 0.0_wp) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): particle is not star-shaped "// &
                          "about its centre (r = "//to_string(surf%rmin)//")", error_code%not_star)
         return
      end if
      allocate (rt(nt, 2 * nt))
      call outer_radii(surf, thickness, rt, report)
      if (.not. all(rt >= surf%r .and. rt < huge(1.0_wp))) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): outer radius not found "// &
                          "in some directions")
         return
      end if
      call fit_outer(surf, rt, cap, .not. present(order), thickness, fit_tol, outer, report)
      if (report%fit_residual > max_fit_residual * thickness) then
         call fatal_error(error, "shell of "//name//" (t = "//to_string(thickness)//"): fit residual "// &
                          to_string(report%fit_residual)//" at order "//to_string(report%order)// &
                          " exceeds "//to_string(max_fit_residual)//" t; use a finer grid or higher order")
         return
      end if
   end subroutine build_shell

   !> Build nested layers at cumulative distances t_1 < t_2 < ... from the particle surface.
   !> Each layer's outer surface is built from the particle itself (exact distances, no
   !> accumulation of fit errors); reports(k)%layer_volume is the volume between layers k-1 and k
   !> and reports(k)%layer_fraction that volume over the volume inside the outermost layer.
   subroutine build_layers(shape, thicknesses, outers, reports, error, label, ntheta, order, fit_tol)
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
      character(len=:), allocatable :: name
      real(wp) :: inner
      integer :: k, nl

      name = "particle"
      if (present(label)) name = label
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
      allocate (outers(nl), reports(nl))
      do k = 1, nl
         call build_shell(shape, thicknesses(k), outers(k), reports(k), error, name//" layer "//to_string(k), &
                          ntheta, order, fit_tol)
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
   pure subroutine fit_outer(surf, rt, cap, search, t, fit_tol, outer, report)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: rt(:, :)
      integer, intent(in) :: cap
      logical, intent(in) :: search
      real(wp), intent(in) :: t
      real(wp), intent(in), optional :: fit_tol
      type(sh_expansion_type), intent(out) :: outer
      type(shell_report_type), intent(inout) :: report
      real(wp), allocatable :: a(:, :), b(:, :), fit(:, :)
      real(wp) :: target, res
      integer :: lo, hi, mid, best

      target = default_fit_tol * t
      if (present(fit_tol)) target = fit_tol * t
      allocate (a(0:cap, 0:cap), b(0:cap, 0:cap), fit(size(rt, 1), size(rt, 2)))
      call sh_analyze(surf%grid, rt, cap, a, b)
      call new_sh_expansion_real(outer, a, b)
      best = cap
      if (search) then
         call sh_synthesize(surf%grid, outer, fit)
         res = maxval(abs(rt - fit))
         if (res <= target) then
            lo = 0
            hi = cap
            do while (lo < hi)
               mid = (lo + hi) / 2
               call sh_synthesize(surf%grid, outer, fit, nused=mid)
               if (maxval(abs(rt - fit)) <= target) then
                  hi = mid
               else
                  lo = mid + 1
               end if
            end do
            best = lo
         end if
      end if
      call new_sh_expansion_real(outer, a(0:best, 0:best), b(0:best, 0:best))
      call sh_synthesize(surf%grid, outer, fit)
      report%order = best
      report%fit_residual = maxval(abs(rt - fit))
      report%particle_volume = grid_volume(surf, surf%r)
      report%outer_volume = grid_volume(surf, fit)
      report%shell_volume = report%outer_volume - report%particle_volume
      report%shell_fraction = report%shell_volume / report%outer_volume
      report%layer_volume = report%shell_volume
      report%layer_fraction = report%shell_fraction
   end subroutine fit_outer

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
