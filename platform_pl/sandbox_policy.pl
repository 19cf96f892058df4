:- module(sandbox_policy,
          [ policy_safe_goal/1,         % :Goal
            policy_refusal/3,           % +Module, +Goal, -Why
            reserved_ball/1,            % ?Ball
            safe_library/1              % +Name
          ]).
:- use_module(library(sandbox), [safe_goal/1]).

:- meta_predicate policy_safe_goal(:).
:- use_module(library(prolog_wrap), [wrap_predicate/4]).
:- use_module(library(prolog_format), [format_spec/2]).
:- autoload(library(lists), [member/2]).
:- autoload(library(occurs), [sub_term/2]).
:- use_module(guest_limits, [guest_hazard/1, guest_static_refusal/2, guest_context/1]).

/** <module> What library(sandbox) accepts and mobile code may still not do

library(sandbox) was written for a query that runs once and returns
(SWISH, pengines); mobile code is a guest in a long-lived process that
runs other guests. A few predicates the sandbox deems safe change the
process or run goals that were never checked, so this module refuses
them, whatever module calls them, at any depth of the sandbox's walk
(library code reached from an agent included): its rule wraps the
sandbox's walker (sandbox:safe/5, with library(prolog_wrap)) and throws
the sandbox's own error, permission_error(call, sandboxed, Goal), with
the reason as context. The families and why each is refused are listed
in code_safety.pl's module comment; policy_refusal/3 is the table.
*/

%!  policy_refusal(+Module, +Goal, -Why) is semidet.
%
%   True if Goal, called in Module, is refused although library(sandbox)
%   would accept it; Why is an atom saying why.

policy_refusal(_, G, _) :-
    var(G),
    !,
    fail.
policy_refusal(M0, G0, Why) :-
    strip_module(M0:G0, M, G),
    callable(G),
    definition(M, G, D),
    functor(G, Name, Arity),
    refused(D:Name/Arity, G, Why),
    !.

%   The module that defines G as seen from M: system for built-ins.
definition(M, G, D) :-
    (   catch(predicate_property(M:G, imported_from(D0)), _, fail)
    ->  D = D0
    ;   catch(predicate_property(system:G, defined), _, fail),
        catch(predicate_property(system:G, system), _, fail)
    ->  D = system
    ;   D = M
    ).

%   refused(+Module:Name/Arity, +Goal, -Why)
refused(system:put_attr/3, _, 'attribute hooks: the value''s hooks run goals nobody checked').
refused(system:put_attrs/2, _, 'attribute hooks: the value''s hooks run goals nobody checked').
refused('$attvar':freeze/2, _, 'coroutines: the goal runs at a later unification').
refused(when:when/2, _, 'coroutines: the goal runs at a later unification').
refused(dif:dif/2, _, 'coroutines: attribute hooks').
refused('$messages':print_message/2, _, 'messages: message hooks and ~@ in a message run goals').
refused('$messages':message_to_string/2, _, 'messages: ~@ in a message runs goals').
refused('$messages':print_message_lines/3, _, 'messages: ~@ in a message runs goals').
refused('$messages':translate_message/3, _, 'messages: ~@ in a message runs goals').
refused(system:format/1, G, Why) :- format_refused(G, 1, Why).
refused(system:format/2, G, Why) :- format_refused(G, 1, Why).
refused(system:format/3, G, Why) :- format_refused(G, 2, Why).
refused(system:set_prolog_flag/2, _, 'flags: they change the whole process').
refused(system:create_prolog_flag/3, _, 'flags: they change the whole process').
refused('$syspreds':set_prolog_stack/2, _, 'flags: stack limits are the platform''s').
refused(system:current_prolog_flag/2, G, Why) :-
    arg(1, G, Flag),
    \+ ( atom(Flag), readable_flag(Flag) ),
    Why = 'flags: only flags that describe the arithmetic and syntax may be read (argv is a secret)'.
refused('$tabling':F/A, _, 'tabling: tables outlive the call and are shared') :-
    tabling(F/A).
refused(system:use_module/1, _, 'loading: a library changes the whole process').
refused(system:use_module/2, _, 'loading: a library changes the whole process').
refused(system:load_files/2, _, 'loading: a library changes the whole process').
refused(system:b_getval/2, _, 'global variables: agents run in the platform''s pooled threads').
refused(system:b_setval/2, _, 'global variables: agents run in the platform''s pooled threads').
refused(system:nb_getval/2, _, 'global variables: agents run in the platform''s pooled threads').
refused('$syspreds':nb_setval/2, _, 'global variables: agents run in the platform''s pooled threads').
refused(system:nb_linkval/2, _, 'global variables: agents run in the platform''s pooled threads').
refused(system:nb_current/2, _, 'global variables: agents run in the platform''s pooled threads').
refused(system:abort/0, _, 'abort: it unwinds the platform''s worker, not the agent').
refused(system:setup_call_cleanup/3, _, 'cleanup: a cleanup runs after the agent was stopped').
refused(system:call_cleanup/2, _, 'cleanup: a cleanup runs after the agent was stopped').
refused(system:setup_call_catcher_cleanup/4, _, 'cleanup: a cleanup runs after the agent was stopped').
refused(system:call_cleanup/3, _, 'cleanup: a cleanup runs after the agent was stopped').
refused(system:catch/3, G, Why) :- catcher_refused(G, Why).
refused(system:catch_with_backtrace/3, G, Why) :- catcher_refused(G, Why).
refused(system:throw/1, throw(Ball), 'throw: the ball could be one of the platform''s stops') :-
    could_be_reserved(Ball).
refused(system:clause/2, clause(H, _), 'clause/2: only of a known predicate') :-
    var(H).
refused(system:'$'/1, _, '$/1: the sandbox takes its own definition, $(G) :- $(G), as proof that G is safe').
refused(system:at_halt/1, _, 'at_halt/1: the goal runs when the node halts, unchecked').
refused(system:cancel_halt/1, _, 'cancel_halt/1: halting is the node''s').
refused(arithmetic:arithmetic_function/1, _, 'arithmetic_function/1: a table of the whole process').
refused(predicate_options:predicate_options/3, _, 'predicate_options/3: a table of the whole process').
refused(settings:F/A, _, 'settings: the node''s configuration') :-
    memberchk(F/A, [setting/2, setting/4, current_setting/1, set_setting/2]).
refused(prolog:translate_bindings/5, _, 'toplevel internals').
refused(_:F/A, G, Why) :-
    guest_hazard(F/A),
    guest_static_refusal(G, Why).

tabling(abolish_all_tables/0).
tabling('$wrap_tabled'/2).
tabling('$moded_wrap_tabled'/5).
tabling(abolish_table_subgoals/1).
tabling(current_table/2).
tabling(tnot/1).
tabling(not_exists/1).

%   ~W writes with options chosen by the caller, and portray_goal(G)
%   among them calls G: a goal the sandbox does not see.
format_refused(G, FormatArg, Why) :-
    arg(FormatArg, G, Format),
    (   var(Format)
    ->  fail                    % the sandbox refuses it (instantiation)
    ;   catch(format_spec(Format, Spec), _, fail)
    ->  memberchk(escape(_, _, 'W'), Spec),
        Why = 'format: ~W takes write options that call goals (portray_goal)'
    ;   Why = 'format: a format this node cannot parse'
    ).

catcher_refused(G, 'catch: the catcher could take the platform''s stop of the agent') :-
    arg(2, G, Catcher),
    could_be_reserved(Catcher).

could_be_reserved(Ball) :-
    (   var(Ball)
    ->  true
    ;   reserved_ball(R),
        \+ Ball \= R
    ),
    !.

%!  reserved_ball(?Ball) is nondet.
%
%   Exceptions the platform throws into an agent's thread to stop it;
%   mobile code may neither catch nor throw them.

reserved_ball('$aborted').
reserved_ball(unwind(_)).
reserved_ball('$dfrl_purged').
reserved_ball('$dfrl_bound'(_)).
reserved_ball(time_limit_exceeded).
reserved_ball(time_limit_exceeded(_)).

%   Flags that tell how arithmetic and syntax behave; the rest (argv,
%   os_argv, executable, home, pid, tmp_dir, the platform's own) are
%   the process's.
readable_flag(bounded).
readable_flag(max_integer).
readable_flag(min_integer).
readable_flag(max_tagged_integer).
readable_flag(min_tagged_integer).
readable_flag(float_max).
readable_flag(float_min).
readable_flag(float_max_integer).
readable_flag(max_arity).
readable_flag(max_char_code).
readable_flag(integer_rounding_function).
readable_flag(prefer_rationals).
readable_flag(rational_syntax).
readable_flag(float_overflow).
readable_flag(float_zero_div).
readable_flag(float_undefined).
readable_flag(float_underflow).
readable_flag(float_rounding).
readable_flag(float_format).
readable_flag(double_quotes).
readable_flag(back_quotes).
readable_flag(var_prefix).
readable_flag(occurs_check).
readable_flag(character_escapes).
readable_flag(iso).
readable_flag(unknown).
readable_flag(dialect).
readable_flag(version).
readable_flag(version_data).
readable_flag(on_error).
readable_flag(on_warning).

%!  safe_library(+Name) is semidet.
%
%   Name (as in library(Name)) may be loaded by a program a peer sent:
%   libraries of pure predicates whose loading installs no hook, starts
%   nothing and changes no flag.

safe_library(lists).
safe_library(apply).
safe_library(pairs).
safe_library(aggregate).
safe_library(assoc).
safe_library(yall).
safe_library(ordsets).
safe_library(ugraphs).
safe_library(rbtrees).
safe_library(option).
safe_library(error).
safe_library(solution_sequences).
safe_library(dicts).
safe_library(random).
safe_library(nb_set).
safe_library(heaps).
safe_library(occurs).
safe_library(sort).
safe_library(dcg/basics).
safe_library(dcg/high_order).
safe_library(strings).

		 /*******************************
		 *   SIZES OF WORK DONE IN C	*
		 *******************************/

%   unchecked_builtin(+Goal, +Module, +Parents, -Why): Goal, as the walk
%   meets it, is one of the predicates guest_limits.pl holds a checked
%   version of, and it is reached in a way that skips the checked
%   version: guest code resolves unqualified calls (and meta-calls of
%   unqualified closures) in its own module, which takes the checked
%   ones; an explicit module does not. Refused: system:is(X, E),
%   call(lists:is, X, E), apply:maplist(is, Xs, Es) (the closure is
%   resolved in apply), lists:sum_list(L, S). Allowed: a library's own
%   clause calling it (lists:sum_list/3 adding), which is reached from
%   guest code only through a library predicate that is itself checked
%   or computes on its own values.
unchecked_builtin(G, M, Parents, Why) :-
    nonvar(G),
    strip_module(M:G, Q, Plain),
    callable(Plain),
    functor(Plain, Name, Arity),
    guest_hazard(Name/Arity),
    \+ guest_context(Q),
    (   nonvar(G), G = _:_
    ->  true
    ;   Parents == []
    ->  true
    ;   Parents = [P|_],
        \+ library_clause_calls(P, Q, Name/Arity)
    ),
    format(atom(Why), 'sizes: ~q, called in ~q, skips the size checks of \c
                       guest_limits.pl (call it without a module)', [Name/Arity, Q]).

%   The walk met the goal in a clause of Parent's predicate, defined in
%   Module, whose body calls Name/Arity (a library's own call, as
%   lists:numlist/3 calling must_be/2), not in a meta-argument of Parent
%   (apply:maplist(is, Xs, Es) resolves `is` in apply, but maplist's
%   clauses do not call is/2).
library_clause_calls(Parent, Module, Name/Arity) :-
    nonvar(Parent),
    strip_module(Parent, PM, PG),
    callable(PG),
    functor(PG, PN, PA),
    functor(Head, PN, PA),
    (   catch(predicate_property(PM:Head, imported_from(D)), _, fail)
    ->  true
    ;   D = PM
    ),
    D == Module,
    catch(clause(D:Head, Body), _, fail),
    sub_term(T, Body),
    callable(T),
    functor(T, Name, Arity),
    !.

		 /*******************************
		 *     THE WRAPPER ON THE WALK	*
		 *******************************/

%!  policy_safe_goal(:Goal) is det.
%
%   As library(sandbox)'s safe_goal/1, and Goal calls nothing this
%   module refuses. The sandbox's own refusal is reported first (it
%   names the goal the user wrote, e.g. halt/1 rather than the flag that
%   halt/0 reads); else the first goal of the walk that the policy
%   refuses, as permission_error(call, sandboxed, Goal) with context
%   sandbox(Goal, [policy(Why)|Parents]).
%
%   @error permission_error(call, sandboxed, Goal)

policy_safe_goal(Goal) :-
    setup_call_cleanup(
        nb_setval(dfrl_policy_refusal, none),
        ( safe_goal(Goal),
          nb_getval(dfrl_policy_refusal, Refusal)
        ),
        nb_delete(dfrl_policy_refusal)),
    (   Refusal == none
    ->  true
    ;   throw(Refusal)
    ).

%   Every goal the sandbox's walk meets passes here first. Within
%   policy_safe_goal/1 a refused goal is noted (the first one) and taken
%   as a leaf, so that the walk goes on and the sandbox may still refuse
%   something itself; elsewhere it is refused at once.
policy_check(G, M, Parents, Walk) :-
    (   (   unchecked_builtin(G, M, Parents, Why)
        ->  true
        ;   policy_refusal(M, G, Why)
        )
    ->  strip_module(M:G, Q, Plain),
        Error = error(permission_error(call, sandboxed, Q:Plain),
                      sandbox(Q:Plain, [policy(Why)|Parents])),
        (   nb_current(dfrl_policy_refusal, Seen)
        ->  (   Seen == none
            ->  nb_setval(dfrl_policy_refusal, Error)
            ;   true
            )
        ;   throw(Error)
        )
    ;   call(Walk)
    ).

:- wrap_predicate(sandbox:safe(G, M, Parents, Safe0, Safe), dfrl_policy, Walk,
                  ( sandbox_policy:policy_check(G, M, Parents, Walk)
                  ->  ( var(Safe) -> Safe = Safe0 ; true )
                  )).
